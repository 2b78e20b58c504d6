"""Run every benchmark in this folder, one after the other, and print their figures.

    python bench/run.py            # all
    python bench/run.py fit render # only those whose module name contains a word given
    python bench/run.py sigma_mc   # slow, optional (OPTIONAL = True): only when named

Each bench module has `run() -> dict` and prints its own table when run alone; this runner
calls each module's `main()` if it has one, else prints `run()`'s figures. Figures go in
docs/performance.md. Run on an otherwise idle machine: the targets are wall-clock times.
"""

from __future__ import annotations

import importlib.util
import json
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main(argv: list[str]) -> int:
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
                result = module.main() if module.main.__code__.co_argcount == 0 else module.main([])
                if isinstance(result, int) and result != 0:
                    failed.append(path.stem)
            else:
                print(json.dumps(module.run(), indent=2, default=str))
        except Exception as exc:  # keep going: one broken bench must not hide the others
            failed.append(path.stem)
            print(f"{path.stem} failed: {type(exc).__name__}: {exc}")
        print(f"({time.perf_counter() - start:.1f} s)", flush=True)
    if failed:
        print(f"\nfailed: {', '.join(failed)}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
