"""Run every benchmark in this folder, one after the other, and print their figures.

    .venv/bin/python bench/run.py            # all (use the venv's Python: plain `python`
                                              # lacks numpy & co. on a fresh machine)
    .venv/bin/python bench/run.py fit render # only those whose module name contains a word
    .venv/bin/python bench/run.py --quick    # shorter runs where a bench offers them
    .venv/bin/python bench/run.py sigma_mc   # slow, optional (OPTIONAL = True): only when named

Each bench module has `run() -> dict` and prints its own table when run alone; this runner
calls each module's `main()` if it has one (`--quick` is passed to a `main(argv)`), else
prints `run()`'s figures as a table. Figures go in docs/performance.md. Run on an otherwise
idle machine: the targets are wall-clock times.
"""

from __future__ import annotations

import importlib.util
import json
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main(argv: list[str]) -> int:
    try:
        import numpy  # noqa: F401  (every bench needs it; a system Python may lack it)
    except ImportError:
        print(f"bench/run.py: {sys.executable} cannot import numpy: run it with the venv's "
              "Python, e.g. .venv/bin/python bench/run.py", file=sys.stderr)
        return 2
    flags = [a for a in argv if a.startswith("--")]
    argv = [a for a in argv if not a.startswith("--")]
    modules = sorted(p for p in HERE.glob("bench_*.py"))
    if argv:
        modules = [p for p in modules if any(word in p.stem for word in argv)]
    else:  # slow, optional benches (OPTIONAL = True) run only when asked for by name
        modules = [p for p in modules if "\nOPTIONAL = True" not in p.read_text()]
    sys.path.insert(0, str(HERE.parent))
    failed = []
    for path in modules:
        print(f"\n=== {path.stem} ===", flush=True)
        spec = importlib.util.spec_from_file_location(path.stem, path)
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        start = time.perf_counter()
        try:
            spec.loader.exec_module(module)
            if hasattr(module, "main"):
                own = [f for f in flags if f in path.read_text()]  # flags it knows
                result = (module.main() if module.main.__code__.co_argcount == 0
                          else module.main(own))
                if isinstance(result, int) and result != 0:
                    failed.append(path.stem)
            else:
                print_table(module.run())
        except Exception as exc:  # keep going: one broken bench must not hide the others
            failed.append(path.stem)
            print(f"{path.stem} failed: {type(exc).__name__}: {exc}")
        print(f"({time.perf_counter() - start:.1f} s)", flush=True)
    if failed:
        print(f"\nfailed: {', '.join(failed)}")
    return 1 if failed else 0


def print_table(figures: object) -> None:
    """A bench's figures as a table: a dict of dicts as rows x columns, a flat dict as
    name / value lines, anything else as JSON."""
    if isinstance(figures, dict) and figures and all(isinstance(v, dict)
                                                     for v in figures.values()):
        columns = list(dict.fromkeys(k for row in figures.values() for k in row))
        width = max(len(str(name)) for name in figures) + 2
        print(f"{'':<{width}}" + "".join(f"{c:>{max(12, len(c) + 2)}}" for c in columns))
        for name, row in figures.items():
            print(f"{str(name):<{width}}" + "".join(
                f"{_cell(row.get(c)):>{max(12, len(c) + 2)}}" for c in columns))
    elif isinstance(figures, dict):
        width = max((len(str(k)) for k in figures), default=0) + 2
        for key, value in figures.items():
            print(f"{str(key):<{width}}{_cell(value)}")
    else:
        print(json.dumps(figures, indent=2, default=str))


def _cell(value: object) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, dict | list):
        return json.dumps(value, default=str)
    return "-" if value is None else str(value)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
