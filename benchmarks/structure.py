"""Structure figures of the host and the firmware: where the seams hold (issue 31).

Prints, for the tree this script stands in:

* `run_job`'s parameter count (the one function that runs a job on any controller);
* where a controller's name is read: the function that imports a controller by its name
  (`controller_for`, the one place that should), and any comparison with, or mapping key of,
  the controllers' names ("fivebar", "grbl") in `fivebar_host/`;
* which host modules write G1/G6/M280 text: string literals and f-strings that begin with
  those words (docstrings and comments do not count; the devices under `devices/`, which
  parse and answer the text as a machine does, are listed apart);
* imports of `_private` names from another module (`from a.b import _c`);
* classes in `fivebar_host/server/` with more than one base that is not a framework class;
* the firmware's `extern` variables (data, not functions) in `firmware/fivebar/`;
* files over 600 lines and functions over 100 lines in `fivebar_host/` and `kinematics/`;
* with `--mypy`, the error count of `mypy --strict fivebar_host kinematics`.

Run: python benchmarks/structure.py [--mypy]
"""

from __future__ import annotations

import argparse
import ast
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
HOST = ROOT / "fivebar_host"
CONTROLLER_NAMES = ("fivebar", "grbl")
#: Bases a server class may add to its own without counting as multiple inheritance.
FRAMEWORK_BASES = {"BaseModel", "Exception", "RuntimeError", "ValueError", "KeyError",
                   "FivebarError", "Thread", "threading.Thread", "Protocol", "Enum", "str",
                   "int", "NamedTuple", "TypedDict", "Generic"}
MOTION_WORDS = re.compile(r"^(G1|G6|M280)(\s*[A-Z]|$)")


def py_files(*roots: Path) -> Iterator[Path]:
    for root in roots:
        yield from sorted(p for p in root.rglob("*.py") if "__pycache__" not in p.parts)


def rel(p: Path) -> str:
    return str(p.relative_to(ROOT))


def parse(p: Path) -> ast.Module:
    return ast.parse(p.read_text(encoding="utf-8"), filename=str(p))


def run_job_params() -> list[str]:
    """`file:function: n` for every function named run_job."""
    out = []
    for p in py_files(HOST):
        for node in ast.walk(parse(p)):
            if isinstance(node, ast.FunctionDef) and node.name == "run_job":
                a = node.args
                n = len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs)
                n += (a.vararg is not None) + (a.kwarg is not None)
                out.append(f"{rel(p)}:{node.lineno} run_job: {n} parameters")
    return out


def controller_name_reads() -> list[str]:
    """Places that read a controller's name: functions that import a controller's module by
    its name (`importlib.import_module` in `fivebar_host/controllers/`), and comparisons
    with, or mapping keys of, the names of the controllers."""
    out = []
    for p in py_files(HOST / "controllers"):
        for node in ast.walk(parse(p)):
            if isinstance(node, ast.FunctionDef) and any(
                    isinstance(c, ast.Call) and _called(c) == "import_module"
                    for c in ast.walk(node)):
                out.append(f"{rel(p)}:{node.lineno} {node.name} (imports the named module)")
    for p in py_files(HOST):
        for node in ast.walk(parse(p)):
            consts: list[ast.expr] = []
            if isinstance(node, ast.Compare):
                consts = [node.left, *node.comparators]
                consts += [e for c in node.comparators if isinstance(c, ast.Tuple | ast.List
                                                                     | ast.Set) for e in c.elts]
            elif isinstance(node, ast.Dict):
                consts = [k for k in node.keys if k is not None]
            elif isinstance(node, ast.MatchValue):
                consts = [node.value]
            for c in consts:
                if isinstance(c, ast.Constant) and c.value in CONTROLLER_NAMES:
                    out.append(f"{rel(p)}:{c.lineno} {c.value!r}")
    return sorted(set(out))


def _docstrings(tree: ast.Module) -> set[int]:
    ids = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                ids.add(id(body[0].value))
    return ids


def motion_text_writers() -> dict[str, list[int]]:
    """Module → lines of string literals / f-strings that begin with G1, G6 or M280."""
    out: dict[str, list[int]] = {}
    for p in py_files(HOST):
        tree = parse(p)
        docs = _docstrings(tree)
        inner: set[int] = set()  # parts of f-strings, and names looked up, not written
        for node in ast.walk(tree):
            if isinstance(node, ast.JoinedStr):
                inner.update(id(v) for v in node.values)
            elif isinstance(node, ast.Compare):
                inner.update(id(v) for v in (node.left, *node.comparators))
            elif isinstance(node, ast.Dict):
                inner.update(id(v) for v in (*node.keys, *node.values) if v is not None)
        for node in ast.walk(tree):
            text = None
            if isinstance(node, ast.Constant) and isinstance(node.value, str) \
                    and id(node) not in docs and id(node) not in inner:
                text = node.value
            elif isinstance(node, ast.JoinedStr) and node.values \
                    and isinstance(node.values[0], ast.Constant):
                text = str(node.values[0].value)
            writes = text is not None and MOTION_WORDS.match(text.lstrip()) is not None
            calls = isinstance(node, ast.Call) and _called(node) in ("g1", "m280")
            if writes or calls:
                out.setdefault(rel(p), []).append(node.lineno)
    return out


def _called(call: ast.Call) -> str:
    f = call.func
    return f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else ""


def motion_text_readers() -> dict[str, list[int]]:
    """Module → lines of regular expressions that read G1/G6 text back (its words)."""
    out: dict[str, list[int]] = {}
    for p in py_files(HOST):
        for node in ast.walk(parse(p)):
            if isinstance(node, ast.Call) and _called(node) == "compile" and node.args \
                    and isinstance(node.args[0], ast.Constant) \
                    and isinstance(node.args[0].value, str) \
                    and re.search(r"G1|G6|\[AB|\(\[AB|\[ABPS", node.args[0].value):
                out.setdefault(rel(p), []).append(node.lineno)
    return out


def private_imports() -> list[str]:
    """`from x import _name` where x is another module of this project."""
    out = []
    for p in py_files(HOST, ROOT / "kinematics"):
        for node in ast.walk(parse(p)):
            if isinstance(node, ast.ImportFrom) and node.module \
                    and node.module.split(".")[0] in ("fivebar_host", "kinematics"):
                for a in node.names:
                    if a.name.startswith("_") and not a.name.startswith("__"):
                        out.append(f"{rel(p)}:{node.lineno} {node.module}.{a.name}")
    return out


def multi_base_server_classes() -> list[str]:
    out = []
    for p in py_files(HOST / "server"):
        for node in ast.walk(parse(p)):
            if isinstance(node, ast.ClassDef):
                own = [ast.unparse(b) for b in node.bases
                       if ast.unparse(b).split("[")[0] not in FRAMEWORK_BASES]
                if len(own) > 1:
                    out.append(f"{rel(p)}:{node.lineno} {node.name}({', '.join(own)})")
    return out


_EXTERN = re.compile(r"^\s*extern\s+(?!\"C\")[^;(]*;", re.M)


def firmware_externs() -> list[str]:
    out = []
    fw = ROOT / "firmware" / "fivebar"
    for p in sorted([*fw.glob("*.h"), *fw.glob("*.c")]):
        text = re.sub(r"/\*.*?\*/", lambda m: "\n" * m.group(0).count("\n"), p.read_text(),
                      flags=re.S)
        for m in _EXTERN.finditer(text):
            line = text.count("\n", 0, m.start()) + 1
            decl = m.group(0).strip()
            # one row per declared name: `extern int a, b;` declares two
            depth, names = 0, 1
            for ch in decl:
                depth += (ch in "[{(") - (ch in "]})")
                names += ch == "," and depth == 0
            out += [f"{rel(p)}:{line} {decl}"] * names
    return out


def long_things() -> tuple[list[str], list[str]]:
    files, funcs = [], []
    for p in py_files(HOST, ROOT / "kinematics"):
        n = len(p.read_text(encoding="utf-8").splitlines())
        if n > 600:
            files.append(f"{rel(p)}: {n} lines")
        for node in ast.walk(parse(p)):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                length = (node.end_lineno or node.lineno) - node.lineno + 1
                if length > 100:
                    funcs.append(f"{rel(p)}:{node.lineno} {node.name}: {length} lines")
    return files, funcs


def mypy_strict() -> str:
    r = subprocess.run([sys.executable, "-m", "mypy", "--strict", "fivebar_host", "kinematics"],
                       cwd=ROOT, capture_output=True, text=True)
    return (r.stdout.strip().splitlines() or ["?"])[-1]


def show(title: str, rows: list[str], figure: str) -> None:
    print(f"{title}: {figure}")
    for r in rows:
        print(f"    {r}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    ap.add_argument("--mypy", action="store_true", help="also run mypy --strict (slow)")
    args = ap.parse_args()
    rj = run_job_params()
    show("run_job", rj, f"{len(rj)} definition(s)")
    names = controller_name_reads()
    show("controller name read", names, f"{len(names)} place(s)")
    writers = motion_text_writers()
    host = {m: v for m, v in writers.items() if "/devices/" not in m}
    devices = {m: v for m, v in writers.items() if "/devices/" in m}
    show("G1/G6/M280 text written by host modules", [f"{m}: lines {v}" for m, v in
                                                       host.items()], f"{len(host)} module(s)")
    show("... by the emulated devices", [f"{m}: lines {v}" for m, v in devices.items()],
         f"{len(devices)} module(s)")
    readers = {m: v for m, v in motion_text_readers().items() if "/devices/" not in m}
    show("G1/G6 text read back by host modules", [f"{m}: lines {v}" for m, v in
                                                   readers.items()], f"{len(readers)} module(s)")
    priv = private_imports()
    show("cross-module imports of _private names", priv, str(len(priv)))
    multi = multi_base_server_classes()
    show("server classes with more than one non-framework base", multi, str(len(multi)))
    ext = firmware_externs()
    show("firmware extern variables", ext, str(len(ext)))
    files, funcs = long_things()
    show("files over 600 lines", files, str(len(files)))
    show("functions over 100 lines", funcs, str(len(funcs)))
    if args.mypy:
        print(f"mypy --strict fivebar_host kinematics: {mypy_strict()}")


if __name__ == "__main__":
    main()
