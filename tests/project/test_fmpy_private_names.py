"""The package uses fmpy through its public names only: no ``from fmpy... import _private`` and no
``fmpy.module._private`` attribute, so an fmpy release that reorganises its internals (the SSP
module's ``_get_parameter_set``, say) cannot break a run. The scenario loader reads SSV files itself."""
from __future__ import annotations

import ast
from pathlib import Path

#: The clone: the folder above this test that holds pyproject.toml (the test may sit in a sub-folder of tests/).
ROOT = next(p for p in Path(__file__).resolve().parents if (p / "pyproject.toml").is_file())
PACKAGE_FOLDERS = ("fmus", "controllers", "harness")


def private_fmpy_names(source: str) -> list[str]:
    """The private fmpy names (a part starting with ``_``) a module's source imports or reads."""
    tree = ast.parse(source)
    aliases = {a.asname or a.name for n in ast.walk(tree) if isinstance(n, ast.Import)
               for a in n.names if a.name.split(".")[0] == "fmpy"}
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "fmpy":
            found += [f"{node.module}.{a.name}" for a in node.names
                      if a.name.startswith("_") or any(p.startswith("_") for p in node.module.split("."))]
        elif isinstance(node, ast.Import):
            found += [a.name for a in node.names
                      if a.name.split(".")[0] == "fmpy" and any(p.startswith("_") for p in a.name.split("."))]
        elif isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__"):
            base = node.value
            while isinstance(base, ast.Attribute):
                base = base.value
            if isinstance(base, ast.Name) and base.id in aliases:
                found.append(f"{ast.unparse(node)}")
    return found


def test_the_package_uses_no_private_fmpy_name() -> None:
    files = [f for folder in PACKAGE_FOLDERS for f in sorted((ROOT / folder).rglob("*.py"))]
    assert any(f.name == "ssp.py" for f in files)
    bad = {str(f.relative_to(ROOT)): names for f in files if (names := private_fmpy_names(f.read_text()))}
    assert not bad, f"private fmpy names used (use fmpy's public API or read the file ourselves): {bad}"


def test_the_check_sees_a_private_name() -> None:
    source = ("from fmpy.ssp.ssd import _get_parameter_set, read_ssd\nimport fmpy.ssp.ssd as fssd\n"
              "def f(p):\n    from fmpy import read_model_description\n    return fssd._resolve(p), fssd.read_ssv\n")
    assert private_fmpy_names(source) == ["fmpy.ssp.ssd._get_parameter_set", "fssd._resolve"]
