"""``docs/api.md``'s table of the Python API beside the command line, generated from the functions'
signatures and from the ``ipcosim run`` parser, so the reference cannot fall behind the code:
``python -m devtools.apidoc --update`` rewrites its ``api:run`` block (``devtools.docblocks``).
"""
from __future__ import annotations

import argparse
import inspect
import sys
from pathlib import Path

#: Name of the generated block in docs/api.md (``<!-- api:run -->`` ... ``<!-- /api:run -->``).
BLOCK = "api:run"
DOC = Path(__file__).resolve().parents[1] / "docs" / "api.md"


def python_call(function: object, name: str) -> str:
    """``name(args) -> returns`` from ``function``'s signature (annotations left out but the return's);
    :func:`ipcosim.run`'s ``**more`` is written out as the other fields of :class:`ipcosim.RunOptions`."""
    from ipcosim.harness.api.options import RunOptions

    sig = inspect.signature(function)  # type: ignore[arg-type]
    params = list(sig.parameters.values())
    if name == "ipcosim.run":
        more = inspect.signature(RunOptions).parameters
        params = [p for p in params if p.kind is not inspect.Parameter.VAR_KEYWORD]
        params += [p.replace(kind=inspect.Parameter.KEYWORD_ONLY) for n, p in more.items()
                   if n not in sig.parameters]
    words, star = [], False
    for p in params:
        if p.kind is inspect.Parameter.KEYWORD_ONLY and not star:
            words.append("*")
            star = True
        prefix = "**" if p.kind is inspect.Parameter.VAR_KEYWORD else ""
        words.append(prefix + p.name + ("" if p.default is inspect.Parameter.empty else f"={p.default!r}"))
    returns = sig.return_annotation
    returns = returns if isinstance(returns, str) else getattr(returns, "__name__", str(returns))
    return f"{name}({', '.join(words)}) -> {returns}"


def _rows() -> list[tuple[str, str, str]]:
    import ipcosim
    from ipcosim.harness.api.describe import describe

    return [(python_call(ipcosim.run, "ipcosim.run"), command_line(), "one run"),
            (python_call(ipcosim.scenarios, "ipcosim.scenarios"), "ipcosim list", "the shipped scenarios"),
            (python_call(describe, "ipcosim.harness.api.describe.describe"), "ipcosim describe SCENARIO [--json]",
             "components, variables, units, start values, what --set may change"),
            (python_call(ipcosim.build, "ipcosim.build"), "ipcosim build",
             "the project's FMUs (unchanged ones are kept)"),
            (python_call(ipcosim.build_fmu, "ipcosim.build_fmu"), "", "your own FMU script, cached by content"),
            (python_call(ipcosim.linearize, "ipcosim.linearize"), "ipcosim linearize PLANT",
             "A, B, C, D about upright")]


def command_line() -> str:
    """``ipcosim run SCENARIO|PATH --stop-time S ...``: every option of the parser, in its order."""
    from ipcosim.harness.cli import build_parser, parsers

    p = next(q for q in parsers(build_parser()) if q.prog == "ipcosim run")
    words = ["ipcosim run"]
    for action in p._actions:  # noqa: SLF001 -- argparse offers no public walk
        if isinstance(action, argparse._HelpAction):  # noqa: SLF001
            continue
        if not action.option_strings:
            words.append(action.metavar or action.dest.upper())
        elif action.nargs == 0:
            words.append(action.option_strings[0])
        else:
            value = "{" + ",".join(action.choices) + "}" if action.choices else action.metavar or action.dest.upper()
            words.append(f"{action.option_strings[0]} {value}")
    return " ".join(words)


def render() -> str:
    """The block's text: the table."""
    cell = lambda text: f"`{text}`" if text else ""
    lines = ["| Python | command line | |", "|---|---|---|"]
    lines += [f"| {cell(py)} | {cell(cli.replace('|', chr(92) + '|'))} | {what} |" for py, cli, what in _rows()]
    return "\n".join(lines) + "\n"


def block(part: str) -> str:
    """The text of the block ``api:<part>`` (``devtools.docblocks``): ``run``, the table."""
    if part != "run":
        raise KeyError(f"no api block {part!r} (the one block is {BLOCK})")
    return render()


def update(doc: Path = DOC) -> bool:
    """Rewrite the block in ``doc``; True if it changed."""
    from devtools.docblocks import write

    return write(doc, BLOCK, render())


def main(argv: list[str] | None = None) -> int:
    """``--update``: rewrite docs/api.md; else print the block."""
    parser = argparse.ArgumentParser(prog="python -m devtools.apidoc", allow_abbrev=False,
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--update", action="store_true", help="rewrite the block in docs/api.md")
    args = parser.parse_args(argv)
    if args.update:
        print(f"{DOC}: {'updated' if update() else 'up to date'}")
    else:
        sys.stdout.write(render())
    return 0


if __name__ == "__main__":
    sys.exit(main())
