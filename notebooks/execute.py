#!/usr/bin/env python
"""Execute the notebooks top to bottom and write them back with their outputs (figures
included), so that the repository's web page and the documentation site show them.

    python notebooks/execute.py                  # every notebook, full mode
    python notebooks/execute.py 01 05            # the notebooks whose names start so
    python notebooks/execute.py --quick          # quick mode (JAXROD_QUICK=1), as the tests run them
    python notebooks/execute.py --check          # execute, write nothing; exit 1 if one errors

Each notebook runs in a fresh kernel from the notebooks/ folder (nbclient); a notebook that
raises stops the script with exit status 1 and leaves the committed file as it was. A
notebook is written only when it has run to its end, so an interrupted run resumes by
running again the names that were not reached (each notebook's time is printed).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def execute(path: Path, *, quick: bool = False, timeout: int = 3600, extra_cells=()):
    """The notebook at `path` executed in a fresh kernel from its folder, its stored outputs
    dropped first; `quick` sets `JAXROD_QUICK=1` for the kernel, else it is unset; the sources
    in `extra_cells` run as code cells appended after the notebook's own (the file is untouched;
    the tests read what the kernel holds at the end this way)."""
    import nbclient
    import nbformat

    nb = nbformat.read(path, as_version=4)
    for cell in nb.cells:
        if cell.cell_type == "code":
            cell.outputs, cell.execution_count = [], None
    nb.cells += [nbformat.v4.new_code_cell(src) for src in extra_cells]
    old = os.environ.get("JAXROD_QUICK")  # the kernel inherits this process's environment
    if quick:
        os.environ["JAXROD_QUICK"] = "1"
    else:
        os.environ.pop("JAXROD_QUICK", None)
    try:
        nbclient.NotebookClient(nb, timeout=timeout, kernel_name="python3",
                                resources={"metadata": {"path": str(path.parent)}}).execute()
    finally:
        if old is None:
            os.environ.pop("JAXROD_QUICK", None)
        else:
            os.environ["JAXROD_QUICK"] = old
    return nb


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("names", nargs="*", help="prefixes of notebook names (default: all)")
    ap.add_argument("--quick", action="store_true", help="quick mode (JAXROD_QUICK=1)")
    ap.add_argument("--check", action="store_true", help="execute only; write nothing")
    ap.add_argument("--timeout", type=int, default=3600, help="seconds per cell (default 3600)")
    args = ap.parse_args(argv)
    import nbformat

    paths = sorted(p for p in HERE.glob("*.ipynb") if not args.names or any(p.name.startswith(n) for n in args.names))
    if not paths:
        print(f"no notebook matches {args.names}", file=sys.stderr)
        return 2
    for path in paths:
        t0 = time.perf_counter()
        try:
            nb = execute(path, quick=args.quick, timeout=args.timeout)
        except Exception as e:  # nbclient's CellExecutionError names the cell and its traceback
            print(f"{path.name}: FAILED after {time.perf_counter() - t0:.0f} s\n{e}", file=sys.stderr)
            return 1
        if not args.check:
            nbformat.write(nb, path)
        print(f"{path.name}: {'ran' if args.check else 'executed and written'} in {time.perf_counter() - t0:.0f} s",
              flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
