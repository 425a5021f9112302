"""Docs that hold: every file, section, command and option that README.md and docs/ name exists,
every `ipcosim ...` hint the code prints names options its command takes, and the docstrings and
comments of the installed package cite only what a wheel user has."""
from __future__ import annotations

import argparse
import ast
import glob
import io
import re
import tokenize
import tomllib
from pathlib import Path

import pytest

from devtools.docblocks import splice
from ipcosim.harness.cli import build_parser, parsers

ROOT = Path(__file__).resolve().parents[2]
DOCS = sorted([ROOT / "README.md", ROOT / "examples" / "my-controller" / "README.md", *(ROOT / "docs").glob("*.md")])
#: Top folders a doc may point into; generated ones (build/, out/) need not exist in a checkout.
TRACKED = ("docs", "fmus", "controllers", "harness", "benchmarks", "examples", "ssp", "tests")
PATH_RE = re.compile(r"(?<![\w./-])((?:%s)/[\w./*<>{},-]*[\w*])" % "|".join(TRACKED))
LINK_RE = re.compile(r"\]\(([^)\s]+)\)")
COMMAND_RE = re.compile(r"(?<![\w-])ipcosim ((?:[a-z]+)(?: [a-z]+)?)((?:[^`\n|;#(]*))")


def _docs() -> list[tuple[Path, str]]:
    return [(p, p.read_text(encoding="utf-8")) for p in DOCS]


def _exists(ref: str, base: Path) -> bool:
    ref = ref.rstrip(".,:;")
    if "<" in ref or "{" in ref:      # a pattern such as ssp/<plant>-<controller>/: its folder must exist
        ref = ref.split("<")[0].split("{")[0]
        ref = ref.rsplit("/", 1)[0] if not ref.endswith("/") else ref
    for root in (ROOT, base):
        if glob.glob(str(root / ref)):
            return True
    return False


def _prose(text: str) -> str:
    """A doc without its generated snapshot blocks (``python -m devtools.rooms --write``: room labels)."""
    return splice(text, lambda block: "" if block.tool == "rooms" else None)


def test_every_named_file_exists() -> None:
    missing = [f"{p.relative_to(ROOT)}: {ref}" for p, text in _docs() for ref in PATH_RE.findall(_prose(text))
               if not _exists(ref, p.parent)]
    assert not missing, missing


def _slug(title: str) -> str:
    """GitHub's anchor of a heading."""
    text = re.sub(r"[^\w\- ]", "", title.strip().lower().replace("`", ""))
    return text.replace(" ", "-")


def _anchors(path: Path) -> set[str]:
    return {_slug(m) for m in re.findall(r"^#+ (.+)$", path.read_text(encoding="utf-8"), re.M)}


def test_every_link_and_section_resolves() -> None:
    broken = []
    for p, text in _docs():
        for target in LINK_RE.findall(text):
            if re.match(r"[a-z]+:", target):  # https:, mailto:
                continue
            file, _, anchor = target.partition("#")
            dest = (p.parent / file).resolve() if file else p
            if not dest.exists():
                broken.append(f"{p.relative_to(ROOT)}: {target} (no such file)")
            elif anchor and dest.suffix == ".md" and anchor not in _anchors(dest):
                broken.append(f"{p.relative_to(ROOT)}: {target} (no such section)")
    assert not broken, broken


def _command_options() -> dict[str, set[str]]:
    """``{"run": {"--set", ...}, "rig serve": {...}}``: each sub-command's option strings."""
    out: dict[str, set[str]] = {}
    for p in parsers(build_parser()):
        name = p.prog.removeprefix("ipcosim").strip()
        if name:
            out[name] = {s for a in p._actions for s in a.option_strings}  # noqa: SLF001
    return out


def _code(text: str, markdown: bool = True) -> str:
    """The code of a text, one span a line: backtick spans, and in markdown fenced or indented blocks."""
    spans = re.findall(r"`([^`\n]+)`", text)
    if markdown:
        spans += re.findall(r"^(?: {4}|\t)(.+)$", text, re.M)
        spans += [line for block in re.findall(r"^```[^\n]*\n(.*?)^```", text, re.M | re.S)
                  for line in block.splitlines()]
    return "\n".join(spans)


def _bad_uses(text: str, where: str, commands: dict[str, set[str]]) -> list[str]:
    bad = []
    for words, rest in COMMAND_RE.findall(text):
        parts = words.split()
        name = " ".join(parts) if " ".join(parts) in commands else parts[0]
        if name not in commands:
            bad.append(f"{where}: `ipcosim {words}`: no such command")
            continue
        tail = (" ".join(parts[1:]) + " " + rest) if name == parts[0] else rest
        for option in re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]*)", tail):
            if option not in commands[name] and option != "--help":
                bad.append(f"{where}: `ipcosim {name} ... {option}`: {name} has no {option}")
    return bad


def test_every_command_and_option_named_in_the_docs_exists() -> None:
    commands = _command_options()
    bad = [b for p, text in _docs() for b in _bad_uses(_code(text), str(p.relative_to(ROOT)), commands)]
    assert not bad, bad


def _string_literals(path: Path) -> list[tuple[int, str]]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.JoinedStr):
            text = "".join(v.value if isinstance(v, ast.Constant) else "X" for v in node.values)
            out.append((node.lineno, text))
        elif isinstance(node, ast.Constant) and isinstance(node.value, str):
            out.append((node.lineno, node.value))
    return out


def test_no_hint_names_an_option_its_command_does_not_take() -> None:
    """The hints the code prints (`run ipcosim build --native`, ...): one command each."""
    commands = _command_options()
    bad = []
    for path in sorted(ROOT.glob("harness/**/*.py")) + sorted(ROOT.glob("fmus/**/*.py")):
        for line, text in _string_literals(path):
            bad += _bad_uses(_code(text, markdown=False), f"{path.relative_to(ROOT)}:{line}", commands)
    assert not bad, bad


@pytest.mark.parametrize("option", ["--fmus", "--overrun-budget", "--strict", "--timeout", "--loop", "--quiet"])
def test_the_api_table_names_every_run_option(option: str) -> None:
    from devtools.apidoc import render

    assert option in render()


def test_the_checker_sees_a_wrong_option() -> None:
    commands = _command_options()
    assert _bad_uses("`ipcosim export single-mass-lqr-tap --fmus python`", "x", commands)
    assert _bad_uses("see `harness/bench_plant.py`", "x", commands) == []
    assert not _exists("harness/bench_plant.py", ROOT)
    assert isinstance(build_parser(), argparse.ArgumentParser)


#: What the installed package's docstrings and comments may not cite: files a wheel user does not have
#: (the design contract, the thesis-data page and its sources, the evidence and tooling modules beside the
#: package, the repository's tests and benchmarks).
UNSHIPPED_RE = re.compile(r"DESIGN\.md|thesis-data|\.\./shared|(?<![\w.-])seed/"
                          r"|(?<![\w.-])(?:evidence|devtools)(?:\.[a-z_]|/)"
                          r"|(?<![\w./-])(?:tests|benchmarks)/[\w.]")
DOCS_PAGE_RE = re.compile(r"(?<![\w./-])docs/[\w./-]*?\.md")


def _installed_modules() -> list[Path]:
    """The ``.py`` files of the packages pyproject.toml installs (``ipcosim.x.y`` is the folder ``x/y``)."""
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]
    assert config["package-dir"] == {"ipcosim": "."}
    return [f for name in config["packages"] for f in sorted(ROOT.joinpath(*name.split(".")[1:]).glob("*.py"))]


def _prose_of(source: str) -> list[tuple[int, str]]:
    """``(line, text)`` of every docstring (and bare string statement) and every comment of a module."""
    out = [(node.lineno, node.value.value) for node in ast.walk(ast.parse(source))
           if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant) and isinstance(node.value.value, str)]
    out += [(tok.start[0], tok.string) for tok in tokenize.generate_tokens(io.StringIO(source).readline)
            if tok.type == tokenize.COMMENT]
    return out


def _bad_citations(text: str) -> list[tuple[int, str]]:
    """``(line within text, why)`` of each citation in ``text`` of something that does not ship."""
    bad = []
    for word in re.finditer(r"[^\s`'\"(),;:]+", text):
        line = text.count("\n", 0, word.start())
        if UNSHIPPED_RE.search(word.group(0)):
            bad.append((line, f"cites {word.group(0)}, which a wheel user does not have"))
        bad += [(line, f"cites {ref}, no such page") for ref in DOCS_PAGE_RE.findall(word.group(0))
                if not (ROOT / ref).is_file()]
    return bad


def test_the_installed_package_cites_only_what_ships() -> None:
    modules = _installed_modules()
    assert ROOT / "fmus" / "plant.py" in modules and ROOT / "errors.py" in modules
    assert not any(p.is_relative_to(ROOT / d) for p in modules for d in ("tests", "evidence", "devtools", "benchmarks"))
    bad = [f"{path.relative_to(ROOT)}:{line + offset}: {why}" for path in modules
           for line, text in _prose_of(path.read_text(encoding="utf-8")) for offset, why in _bad_citations(text)]
    assert not bad, bad


def test_the_citation_checker_reads_docstrings_and_comments() -> None:
    source = ('"""Module (see DESIGN.md)."""\nX = 1  # docs/plant.md, and evidence.friction\n'
              'def f():\n    """Measured in ``tests/test_x.py``."""\n    return "DESIGN.md"  # docs/nowhere.md\n')
    found = {line: _bad_citations(text) for line, text in _prose_of(source)}
    assert [len(found[n]) for n in (1, 2, 4, 5)] == [1, 1, 1, 1], found   # the string literal "DESIGN.md" is code
    assert "docs/nowhere.md" in found[5][0][1] and "evidence.friction," in found[2][0][1]
    assert _bad_citations("first line\nsecond, see ../shared/DESIGN.md.") == [
        (1, "cites ../shared/DESIGN.md., which a wheel user does not have")]
    for fine in ("the thesis, App. A.5", "docs/plant.md", "noise_seed/2", "the thesis's evidence.",
                 "ipcosim.harness.studies.runners", "a seeded run", "shared library"):
        assert _bad_citations(fine) == [], fine
    for wrong in ("reference/thesis-data.md", "../shared/DESIGN.md", "../seed/thesis.txt", "devtools/ssp_gen.py",
                  "``devtools.ssp_gen``", "benchmarks/stall_probe.py", "docs/plants.md"):
        assert _bad_citations(wrong), wrong
