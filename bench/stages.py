"""What each stage of the certification path contributes: every input jammed with each stage
on and off.

For each input the default run comes first; each variant then switches one stage off (or, for
a stage that is off by default, on) and runs `calippso.jam` again. A variant whose stage the
default run never called would repeat the default run exactly: it is not run and its row says
"not reached". The runs of the set take about an hour on 2 cores once its inputs are made;
making each N = 8192 quench takes 10–15 minutes more. Run from the repository root:

    python bench/stages.py                                  # the set (~1 h on 2 cores)
    python bench/stages.py --inputs ls-d3-n1024-s1 --variants network_first_off
    python bench/stages.py --cache DIR --json stages.json
    python bench/stages.py --cache DIR --cached-only   # the table, no run

Stages and their switches (a setting where `JamSettings` has one; otherwise a module-level
name replaced for the run, said in the table below):

    network_first_off   JamSettings(network_first="off")
    rounds_off          calippso.certification.network_first.MAX_ROUNDS = 1 (one round per candidate)
    restricted_lp_off   calippso.certification.network_first.lp_network refuses every candidate
    nf_pivots_off       calippso.certification.network_first.pivot_to_jamming refuses (the
                        contact pivots inside network first)
    newton_off          JamSettings(newton=False): no Newton stage after LPs
    verify_on           JamSettings(verify_newton=True)
    cleanup_off         calippso.stages.finish._cleanup keeps the network (least-squares
                        polish only)
    interior_on         JamSettings(crossover="off"): the large-N interior engine at this N
    vertex_lp_loop      JamSettings(network_first="off", crossover="on"): the LP loop alone
                        with vertex LPs, what the large-N engine replaces from 20,000
                        columns on (compare with network_first_off, which takes the engine
                        there)

Per run: certified (converged), stop reason, φ_J, contacts, LPs, wall time, and the stages of
the history (records per stage). With ``--cache`` every input and every run's figures are kept,
so the set can be run in pieces. The summary counts, per variant, the runs it decides (the
certificate changes), the runs whose ending it changes (the stop reason changes), and the
seconds default minus variant (for an "off" variant, minus what the stage saves).
"""

from __future__ import annotations

import argparse
import json
import time
from collections import Counter
from contextlib import contextmanager
from pathlib import Path

import numpy as np

import calippso
from calippso import Boundaries

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data"
#: Where the made inputs are kept when no --cache is given.
INPUTS = ROOT / "bench" / ".stage-inputs"

#: The inputs: name -> how to make (or read) it.
SHARED_FILES = {"skoge-donev": "skoge_donev_N1000_d3_p1e12.dat",
                "mono-fbls": "mono_N1000_fba1e-3_then_ls1e-2_seed11",
                "lognormal-fbls": "lognormal0.2_N1000_fba1e-3_then_ls1e-2_seed13",
                "mono-fb0.6": "mono_N1000_fba1e-3_phinom0.6_seed11"}
LS_INPUTS = {"ls-d3-n1024-s1": (3, 1024, 1), "ls-d3-n1024-s2": (3, 1024, 2),
             "ls-d3-n1024-s3": (3, 1024, 3), "ls-d2-n256-s1": (2, 256, 1),
             "ls-d4-n256-s1": (4, 256, 1), "ls-d5-n256-s1": (5, 256, 1)}
#: Soft quenches in d = 3: name -> (N, target pressure, seed), each at the default target
#: pressure of its size (`generators.default_target_pressure`).
QUENCH_INPUTS = {"quench-d3-n1024": (1024, 1e-6, 1), "quench-d3-n2048": (2048, 1e-6, 1),
                 "quench-d3-n4096": (4096, 1e-6, 1), "quench-d3-n8192-s1": (8192, 1e-7, 1),
                 "quench-d3-n8192-s2": (8192, 1e-7, 2), "quench-d3-n8192-s3": (8192, 1e-7, 3),
                 "quench-d3-n8192-s4": (8192, 1e-7, 4), "quench-d3-n8192-s5": (8192, 1e-7, 5)}
#: Containers, N = 1000 equal spheres in d = 3, seed 1: name -> (generator, kind, axes).
CONTAINER_INPUTS = {"ls-walls-x": ("ls", "walls", ["x"]),
                    "ls-cylinder": ("ls", "cylinder", ["x", "y"]),
                    "quench-walls-xy": ("quench", "walls", ["x", "y"]),
                    "quench-cylinder": ("quench", "cylinder", ["x", "y"])}
CONTAINER_N = 1000
#: Reduced pressure of the LS inputs (that of bench/jam.py).
LS_PRESSURE = 1e5
#: Every run stops after this many LPs or the first LP past this many seconds (it then ends
#: uncertified, stop reason "time_limit"), so that one run holds the CPU lock a few minutes.
MAX_ITERS = 500
TIME_LIMIT = 240.0

#: Variants: name -> (jam options, the function whose call in the default run makes the
#: variant differ, None: always run).
VARIANTS = {
    "network_first_off": ({"network_first": "off"}, None),
    "rounds_off": ({}, "settle_candidate"),
    "restricted_lp_off": ({}, "lp_network"),
    "nf_pivots_off": ({}, "nf_pivot_to_jamming"),
    "newton_off": ({"newton": False}, "lps"),
    "verify_on": ({"verify_newton": True}, "newton_or_pivots"),
    "cleanup_off": ({}, "cleanup"),
    "interior_on": ({"crossover": "off"}, "lps"),
    "vertex_lp_loop": ({"network_first": "off", "crossover": "on"}, None),
}


def _refuse(why: str):
    def refused(*args, **kwargs):
        return None, why
    return refused


def _keep_network(run, state, network):
    """`_cleanup` switched off: the network as it is, with its force balance."""
    from calippso.geometry.contact_network import network_balance
    return network, network_balance(state.search, network, run.boundaries)


def _patches(variant: str) -> list[tuple[object, str, object]]:
    """(module, name, replacement) for the variant's switch."""
    import calippso.certification.network_first as nf
    import calippso.stages.finish as finish
    return {"rounds_off": [(nf, "MAX_ROUNDS", 1)],
            "restricted_lp_off": [(nf, "lp_network", _refuse("restricted LP off"))],
            "nf_pivots_off": [(nf, "pivot_to_jamming", _refuse("pivots off"))],
            "cleanup_off": [(finish, "_cleanup", _keep_network)]}.get(variant, [])


def _counted(calls: Counter, key: str, function):
    def wrapper(*args, **kwargs):
        calls[key] += 1
        return function(*args, **kwargs)
    return wrapper


def _probes(calls: Counter) -> list[tuple[object, str, object]]:
    """Counting wrappers for the functions of `VARIANTS` (default run only)."""
    import calippso.ilp as ilp
    import calippso.certification.network_first as nf
    import calippso.stages.finish as finish
    import calippso.stages.network_first_stage as stage
    return [(stage, "settle_candidate", _counted(calls, "settle_candidate",
                                                 stage.settle_candidate)),
            (nf, "lp_network", _counted(calls, "lp_network", nf.lp_network)),
            (nf, "pivot_to_jamming", _counted(calls, "nf_pivot_to_jamming",
                                              nf.pivot_to_jamming)),
            (ilp, "newton_or_pivots", _counted(calls, "newton_or_pivots",
                                               ilp.newton_or_pivots)),
            (finish, "_cleanup", _counted(calls, "cleanup", finish._cleanup))]


@contextmanager
def patched(replacements):
    saved = [(module, name, getattr(module, name)) for module, name, _ in replacements]
    try:
        for module, name, value in replacements:
            setattr(module, name, value)
        yield
    finally:
        for module, name, value in saved:
            setattr(module, name, value)


def load_input(name: str, cache: Path | None):
    """(packing, network hint or None) of a named input."""
    if name in SHARED_FILES:
        return calippso.read(SHARED / SHARED_FILES[name]), None
    if name in LS_INPUTS:
        d, n, seed = LS_INPUTS[name]
        folder = (cache or INPUTS) / "ls"
        path = folder / f"ls_poisson_d{d}_n{n}_p{LS_PRESSURE:g}_endNone_seed{seed}.npz"
        if not path.exists():
            import generators
            sizes = (generators.diameters.bidisperse(n, 1.4, 0.5, seed=seed) if d == 2
                     else generators.diameters.monodisperse(n))
            made = generators.lubachevsky_stillinger(diameters=sizes, d=d, seed=seed,
                                                     target_pressure=LS_PRESSURE).packing
            path.parent.mkdir(parents=True, exist_ok=True)
            calippso.write(made, path)
        return calippso.read(path), None
    if name in QUENCH_INPUTS:
        n, pressure, seed = QUENCH_INPUTS[name]
        path = (cache or INPUTS) / f"quench_d3_n{n}_p{pressure:g}_seed{seed}.npz"
        if not path.exists():
            import generators
            made = generators.soft_quench(generators.diameters.monodisperse(n), 3, seed=seed,
                                          target_pressure=pressure)
            path.parent.mkdir(parents=True, exist_ok=True)
            np.savez(path, positions=made.packing.positions, diameters=made.packing.diameters,
                     box=made.packing.box, contacts=made.contacts)
        with np.load(path) as stored:
            hint = stored["contacts"]
        return calippso.read(path), hint
    if name in CONTAINER_INPUTS:
        generator, kind, axes = CONTAINER_INPUTS[name]
        path = (cache or INPUTS) / f"{name}_d3_n{CONTAINER_N}_s1.npz"
        if not path.exists():
            import generators
            sizes = generators.diameters.monodisperse(CONTAINER_N)
            boundaries = getattr(Boundaries, kind)(3, axes)
            made = (generators.lubachevsky_stillinger(sizes, d=3, seed=1, boundaries=boundaries,
                                                      target_pressure=LS_PRESSURE)
                    if generator == "ls" else
                    generators.soft_quench(sizes, 3, seed=1, boundaries=boundaries))
            path.parent.mkdir(parents=True, exist_ok=True)
            calippso.write(made.packing, path)
        return calippso.read(path), None
    raise ValueError(f"unknown input {name!r}")


def one_run(packing, hint, options: dict, replacements) -> dict:
    """jam once; its figures."""
    start = time.perf_counter()
    try:
        with patched(replacements):
            result = calippso.jam(packing, network=hint, max_iters=MAX_ITERS,
                                  time_limit=TIME_LIMIT, **options)
    except calippso.JammingError as error:
        return {"certified": False, "stop_reason": "error", "error": str(error)[:200],
                "seconds": time.perf_counter() - start}
    seconds = time.perf_counter() - start
    stages = Counter(str(stage) for stage in result.history["stage"])
    return {"certified": bool(result.converged), "stop_reason": result.stop_reason.value,
            "phi": float(result.phi), "contacts": int(result.n_contacts),
            "lps": int(result.iterations), "seconds": seconds, "stages": dict(stages),
            "last_stage": str(result.history["stage"][-1]) if len(result.history) else ""}


def run_input(name: str, variants: list[str], cache: Path | None,
              cached_only: bool = False) -> list[dict]:
    """The default run of an input and its variants (read from the cache when there; with
    `cached_only`, only those)."""
    stored = cache / "runs" / f"{name}.json" if cache else None
    rows = json.loads(stored.read_text()) if stored and stored.exists() else {}
    if cached_only:
        variants = [v for v in variants if v in rows]
        if "default" not in rows:
            return []
    packing, hint = load_input(name, cache)
    if "default" not in rows:
        calls = Counter()
        rows["default"] = one_run(packing, hint, {}, _probes(calls))
        rows["default"]["calls"] = dict(calls)
        _save(stored, rows)
    default = rows["default"]
    for variant in variants:
        if variant in rows:
            continue
        options, trigger = VARIANTS[variant]
        reached = (trigger is None or (trigger == "lps" and default.get("lps", 0) > 0)
                   or default.get("calls", {}).get(trigger, 0) > 0)
        rows[variant] = (one_run(packing, hint, options, _patches(variant)) if reached
                         else {**{k: v for k, v in default.items() if k != "calls"},
                               "not_reached": True})
        _save(stored, rows)
    return [{"input": name, "n": packing.n, "d": packing.d,
             "container": str(packing.boundaries), "variant": v, **rows[v]}
            for v in ["default", *variants]]


def _save(path: Path | None, rows: dict) -> None:
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(rows, indent=1))


def line(row: dict) -> str:
    stages = " ".join(f"{k}:{v}" for k, v in sorted(row.get("stages", {}).items()))
    mark = " (not reached)" if row.get("not_reached") else ""
    return (f"{row['input']:<18} {row['variant']:<18} {'yes' if row['certified'] else 'NO':>4} "
            f"{row['stop_reason']:<18} {row.get('phi', float('nan')):>11.8f} "
            f"{row.get('contacts', 0):>6} {row.get('lps', 0):>4} {row['seconds']:>8.2f}  "
            f"{stages}{mark}")


def decided(default: dict, variant: dict) -> bool:
    """Whether the switch changes the run's verdict (certified or not)."""
    return default["certified"] != variant["certified"]


def ended(default: dict, variant: dict) -> bool:
    """Whether the switch changes the stage that ends the run (its stop reason)."""
    return default["stop_reason"] != variant["stop_reason"]


def summary(rows: list[dict]) -> list[dict]:
    """Per variant: runs reached, runs decided, and default − variant seconds in all."""
    defaults = {row["input"]: row for row in rows if row["variant"] == "default"}
    table = []
    for variant in VARIANTS:
        mine = [row for row in rows if row["variant"] == variant]
        if not mine:
            continue
        reached = [row for row in mine if not row.get("not_reached")]
        table.append({
            "variant": variant, "runs": len(mine), "reached": len(reached),
            "decided": [row["input"] for row in reached if decided(defaults[row["input"]], row)],
            "ended": [row["input"] for row in reached if ended(defaults[row["input"]], row)],
            "seconds_default_minus_variant": sum(defaults[row["input"]]["seconds"]
                                                 - row["seconds"] for row in reached),
            "lps_variant_minus_default": sum(row.get("lps", 0)
                                             - defaults[row["input"]].get("lps", 0)
                                             for row in reached)})
    return table


ALL_INPUTS = [*SHARED_FILES, *LS_INPUTS, *QUENCH_INPUTS, *CONTAINER_INPUTS]
#: The set of docs/notes/certification-stages.md (the slow FB input at φ ≈ 0.60 and the
#: third LS seed are left out of the default).
DEFAULT_INPUTS = [name for name in ALL_INPUTS if name not in ("mono-fb0.6", "ls-d3-n1024-s3")]
#: Variants of that note (verify_on, interior_on and vertex_lp_loop on request).
DEFAULT_VARIANTS = [name for name in VARIANTS
                    if name not in ("verify_on", "interior_on", "vertex_lp_loop")]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--inputs", nargs="+", default=DEFAULT_INPUTS, choices=ALL_INPUTS)
    parser.add_argument("--variants", nargs="+", default=DEFAULT_VARIANTS,
                        choices=list(VARIANTS))
    parser.add_argument("--cache", type=Path, default=None,
                        help="folder that keeps the LS inputs and every run's figures")
    parser.add_argument("--cached-only", action="store_true",
                        help="print the runs kept in --cache, run nothing")
    parser.add_argument("--json", type=Path, default=None, help="write rows and summary here")
    args = parser.parse_args()
    print(f"{'input':<18} {'variant':<18} {'cert':>4} {'stop':<18} {'phi_J':>11} {'N_c':>6} "
          f"{'LPs':>4} {'wall s':>8}  stages")
    rows = []
    for name in args.inputs:
        for row in run_input(name, args.variants, args.cache, args.cached_only):
            rows.append(row)
            print(line(row), flush=True)
    table = summary(rows)
    print(f"\n{'variant':<18} {'runs':>5} {'reached':>7} {'decided':>7} {'ended':>5} "
          f"{'default-variant s':>17} {'LPs variant-default':>19}  decided / ended")
    for entry in table:
        print(f"{entry['variant']:<18} {entry['runs']:>5} {entry['reached']:>7} "
              f"{len(entry['decided']):>7} {len(entry['ended']):>5} "
              f"{entry['seconds_default_minus_variant']:>17.1f} "
              f"{entry['lps_variant_minus_default']:>19}  {' '.join(entry['decided'])} / "
              f"{' '.join(entry['ended'])}")
    if args.json:
        args.json.write_text(json.dumps({"rows": rows, "summary": table}, indent=1))


if __name__ == "__main__":
    main()
