"""What the network-first stage costs an input that it cannot certify (the LP loop then runs).

Each input is jammed with ``network_first="require"``, which runs the stage alone and raises
`JammingError` when no candidate is certified; the table gives the stage's wall time, how
many candidates it tried (the "guess" records) and whether it certified the input. This is
the time added, before the first LP, to every run of the LP loop with the default
``network_first="auto"``.

    python bench/network_first_cost.py --shared ../shared/data --ls 3:1024:1 3:1024:2
    python bench/network_first_cost.py start.npz --json cost.json

`--ls d:N:seed` makes an LS input to reduced pressure `--pressure` (1e5), monodisperse.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import calippso


def stage_cost(start: calippso.Packing) -> dict:
    """Wall time of the stage alone, its candidates tried and whether it certified."""
    clock = time.perf_counter()
    try:
        result = calippso.jam(start, network_first="require")
        certified, tried = True, int((result.history["stage"] == "guess").sum())
    except calippso.JammingError as error:
        certified = False
        history = error.history
        tried = int((history["stage"] == "guess").sum()) if history is not None else 0
    return {"seconds": time.perf_counter() - clock, "candidates": tried,
            "certified": certified}


def inputs(args: argparse.Namespace) -> list[tuple[str, calippso.Packing]]:
    """The packings named on the command line, the shared folder's files, and LS inputs."""
    found = [(str(path), calippso.read(path)) for path in args.files]
    if args.shared:
        for path in sorted(Path(args.shared).iterdir()):
            if path.name != "README.md":
                found.append((path.name, calippso.read(path)))
    for case in args.ls:
        import generators

        d, n, seed = (int(value) for value in case.split(":"))
        made = generators.lubachevsky_stillinger(generators.diameters.monodisperse(n), d=d,
                                                 target_pressure=args.pressure, seed=seed)
        found.append((f"LS d={d} N={n} seed={seed} p={args.pressure:g}", made.packing))
    return found


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("files", nargs="*", type=Path, help="packing files (calippso.read)")
    parser.add_argument("--shared", help="a folder of packings, every entry read")
    parser.add_argument("--ls", nargs="*", default=[], metavar="d:N:seed")
    parser.add_argument("--pressure", type=float, default=1e5)
    parser.add_argument("--json", type=Path, help="write the rows to this JSON file")
    args = parser.parse_args()
    rows = []
    print(f"{'input':<48} {'stage s':>8} {'candidates':>10} {'certified':>9}", flush=True)
    for name, start in inputs(args):
        row = {"input": name, **stage_cost(start)}
        rows.append(row)
        print(f"{name:<48} {row['seconds']:>8.2f} {row['candidates']:>10} "
              f"{'yes' if row['certified'] else 'no':>9}", flush=True)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
