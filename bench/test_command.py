"""Time the README's test command as a new user meets it: a fresh clone, a fresh virtual
environment, ``python -m pip install ".[test]" && python -m pytest -q``, then the tests a
second time (warm caches).

    python bench/test_command.py --json test_command.json

The clone goes to a temporary folder beside which ``shared`` points at this checkout's
``../shared`` (the tests read the shared data from there). Run it alone on the machine.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
import venv
from pathlib import Path

REPOSITORY = Path(__file__).resolve().parents[1]


def timed(command: list[str], cwd: Path) -> tuple[float, str]:
    """Wall time of `command` (s) and the last line of its output; raises when it fails,
    naming the failed tests."""
    started = time.perf_counter()
    done = subprocess.run(command, cwd=cwd, capture_output=True, text=True)
    seconds = time.perf_counter() - started
    lines = (done.stdout + done.stderr).strip().splitlines()
    if done.returncode != 0:
        failed = [line for line in lines if line.startswith(("FAILED", "ERROR"))]
        raise SystemExit("\n".join([f"{' '.join(command)} failed after {seconds:.0f} s: "
                                    f"{lines[-1] if lines else ''}", *failed]))
    return seconds, lines[-1] if lines else ""


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", type=Path, help="write the row here")
    arguments = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as folder:
        root = Path(folder)
        clone = root / "calippso"
        subprocess.run(["git", "clone", "-q", str(REPOSITORY), str(clone)], check=True)
        (root / "shared").symlink_to(REPOSITORY.parent / "shared")
        venv.create(root / "venv", with_pip=True)
        python = str(root / "venv" / "bin" / "python")
        install, _ = timed([python, "-m", "pip", "install", "--quiet", ".[test]"], clone)
        first, summary = timed([python, "-m", "pytest", "-q"], clone)
        second, _ = timed([python, "-m", "pytest", "-q"], clone)
    row = {"install_s": install, "first_run_s": first, "total_s": install + first,
           "second_run_s": second, "tests": summary}
    print("| install | first run | total | second run | tests |")
    print("|---|---|---|---|---|")
    print(f"| {install:.0f} s | {first:.0f} s | {install + first:.0f} s | {second:.0f} s | "
          f"{summary} |")
    if arguments.json:
        arguments.json.write_text(json.dumps(row, indent=1))


if __name__ == "__main__":
    sys.exit(main())
