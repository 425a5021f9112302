"""One name, one thing: every class the installed package defines has a name no other class of the
package has, so a name in a traceback, a docstring or an import means one class only."""
from __future__ import annotations

import ast
import tomllib
from pathlib import Path

#: The clone: the folder above this test that holds pyproject.toml (the test may sit in a sub-folder of tests/).
ROOT = next(p for p in Path(__file__).resolve().parents if (p / "pyproject.toml").is_file())


def installed_files(root: Path = ROOT) -> list[Path]:
    """The ``.py`` files of the packages ``pyproject.toml`` installs (``ipcosim`` is the root folder,
    ``ipcosim.harness.master`` its ``harness/master``): the wheel's modules, not the clone's tooling."""
    config = tomllib.loads((root / "pyproject.toml").read_text())["tool"]["setuptools"]
    folder = root / config["package-dir"]["ipcosim"]
    files = []
    for package in config["packages"]:
        files += sorted((folder.joinpath(*package.split(".")[1:])).glob("*.py"))
    return files


def class_definitions(files: list[Path], root: Path = ROOT) -> dict[str, list[str]]:
    """Every class name defined in ``files`` (at any depth: in a module, a class or a function),
    with the places (``file:line``) that define it."""
    found: dict[str, list[str]] = {}
    for f in files:
        for node in ast.walk(ast.parse(f.read_text(), str(f))):
            if isinstance(node, ast.ClassDef):
                found.setdefault(node.name, []).append(f"{f.relative_to(root)}:{node.lineno}")
    return found


def duplicates(definitions: dict[str, list[str]]) -> dict[str, list[str]]:
    return {name: places for name, places in definitions.items() if len(places) > 1}


def test_every_class_name_is_defined_once() -> None:
    files = installed_files()
    assert any(f.relative_to(ROOT).as_posix() == "harness/master/system.py" for f in files)
    assert not any(f.relative_to(ROOT).parts[0] in ("tests", "benchmarks", "evidence", "devtools") for f in files)
    definitions = class_definitions(files)
    assert len(definitions) > 150  # the walk reached every room, not one module
    twice = duplicates(definitions)
    assert not twice, "class names defined more than once (name each after what it holds):\n" + "\n".join(
        f"  {name}: {', '.join(places)}" for name, places in sorted(twice.items()))


def test_a_second_definition_is_caught(tmp_path: Path) -> None:
    """The check sees a name defined twice, in two modules or nested in a function of one."""
    (tmp_path / "a.py").write_text("class Variable:\n    pass\n\n\nclass Model:\n    pass\n")
    (tmp_path / "b.py").write_text("def read():\n    class Variable:\n        pass\n    return Variable\n")
    found = class_definitions(sorted(tmp_path.glob("*.py")), tmp_path)
    assert duplicates(found) == {"Variable": ["a.py:1", "b.py:2"]}
