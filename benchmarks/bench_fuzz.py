"""Long fuzz run: at least 1000 generated inputs per reader and a mutated-option run per command.

Prints, per reader and command, how many inputs were accepted (``ok``), refused
with one line (``rejected``) and how many broke the contract (tracebacks,
several lines, leaked warnings, NaN in JSON, hangs), with one example of each
failure. The CI tests run the same generators with a fixed seed and a few
dozen inputs each (tests/cli/test_fuzz.py).

Usage::

    python benchmarks/bench_fuzz.py [--count 1000] [--seed 0] [--only netlist,touchstone] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import random
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from cli import test_fuzz_cases as fc  # noqa: E402
import results_io  # noqa: E402  (benchmarks/: results as JSON)


def run_reader(name: str, count: int, seed: int, tmp: Path, per_command: dict | None = None) -> fc.Tally:
    tally = fc.Tally()
    rng = random.Random(f"{name}-{seed}")
    for i in range(count):
        if name == "netlist":
            path = tmp / f"n{i}.cir"
            path.write_bytes(fc.netlist_case(rng))
            verdict, outcome = fc.check_netlist_cli(path)
            tally.add(verdict, f"{path.read_bytes()[:200]!r} -> {outcome.stderr.strip()[:200] or outcome.exception}")
        elif name == "values":
            text = rng.choice(fc.NASTY_VALUES) if rng.random() < 0.3 else _random_value(rng)
            tally.add(fc.check_value(text), repr(text[:80]))
        elif name == "mat":
            path = fc.mat_case(rng, tmp)
            tally.add(fc.check_measured(path), str(path))
        elif name == "options":
            argv, option = option_case(rng, tmp)
            outcome = fc.run_cli(argv)
            names = option_names(argv, option)
            verdict = fc.judge(outcome, names, json_mode="--json" in argv)
            example = f"{' '.join(a[:60] for a in argv)} -> {outcome.stderr.strip()[:200] or outcome.exception}"
            tally.add(verdict, example)
            if per_command is not None:
                per_command.setdefault(argv[0], fc.Tally()).add(verdict, example)
        else:
            ext, data = fc.FILE_READERS[name](rng)
            path = tmp / f"{name}{i}{ext}"
            path.write_bytes(data)
            tally.add(fc.check_measured(path), f"{data[:200]!r}")
    return tally


def _random_value(rng: random.Random) -> str:
    alphabet = "0123456789.eE+-*/^(){} kmunpfgtMEGxabl_sqrtlogpi\u00b5"
    return "".join(rng.choice(alphabet) for _ in range(rng.randint(1, 24)))


#: Costly commands (a valid run takes seconds to minutes): options whose every value in
#: ``BAD_OPTION_VALUES`` is refused, so that a mutated line never starts the real work.
COSTLY_OPTION_FUZZ: list[tuple[list[str], list[str]]] = [
    (["study", "two-section", "--quick", "--cases", "1", "--quiet", "--out", "{tmp}/study", "--json"],
     ["--workers", "--scheduler", "--seeds", "--snr-db", "--optimisers", "--cases", "--measured"]),
    (["estimate", "--config", "{tmp}/missing.json", "--json"], ["--config"]),
    (["lab", "--quick", "--configs", "LVOC", "--out", "{tmp}/lab.csv", "--seed", "-1", "--json"],
     ["--model", "--netlist", "--configs", "--plots", "--seed"]),
    (["reproduce", "bogus", "--out", "{tmp}/figs", "--json"], ["--out"]),
    (["build-fmu", "--model", "two-section", "--out", "{tmp}/fmu", "--fmi-version", "9", "--json"],
     ["--model", "--port", "--name", "--set", "--config", "--vdc", "--fclk", "--prbs-order", "--out"]),
    (["diagnose", "--measured", str(Path(__file__).resolve().parents[1] / "tests" / "data" / "fuzz" / "good_response.csv"),
      "--rpris", "nan", "--json"], ["--measured", "--segment", "--model", "--netlist", "--port", "--report",
                                     "--lpris", "--cpris", "--rload"]),
]


#: Options that already refuse a costly base line: a rejection may name them instead.
COSTLY_GUARDS = {"lab": ["--seed"], "build-fmu": ["--fmi-version"], "diagnose": ["--rpris"], "reproduce": ["bogus"],
                 "estimate": ["--config"]}


def option_names(argv: list[str], option: str) -> list[str]:
    """Words one of which a refusal of the mutated line must contain."""
    names = [option, option.lstrip("-")] + COSTLY_GUARDS.get(argv[0], [])
    if not option.startswith("-") and argv[1:2] and argv[1].strip():
        names.append(argv[1])  # a bad positional value is named by itself
    return names


def option_case(rng: random.Random, tmp: Path) -> tuple[list[str], str]:
    """A cheap valid command with one option replaced by a random (mostly bad) value.

    One line in three comes from :data:`COSTLY_OPTION_FUZZ` instead: a command
    line already refused for another option (or with an option whose bad
    values are all refused), so that the line is judged without the real work.
    """
    costly = rng.random() < 1 / 3
    base, options = rng.choice(COSTLY_OPTION_FUZZ if costly else fc.OPTION_FUZZ)
    argv = [a.replace("{tmp}", str(tmp)) for a in base]
    option = rng.choice(options)
    value = rng.choice(fc.BAD_OPTION_VALUES) if costly or rng.random() < 0.7 else _random_value(rng)
    if not option.startswith("-"):
        return argv[:1] + [value] + argv[1:], option
    if option in argv:
        argv[argv.index(option) + 1] = value
    else:
        argv[-1:-1] = [option, value]
    return argv, option


READERS = ["netlist", "values", "response-csv", "multisegment-csv", "waveform-csv", "touchstone", "e4990a",
           "mag-phase-rows", "mat", "options"]


def _open_files() -> int:
    """Open file descriptors of this process (a leak in a reader shows here)."""
    try:
        return len(os.listdir("/proc/self/fd"))
    except OSError:
        return -1


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=1000, help="inputs per reader (default 1000)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--only", help="comma-separated readers: " + ",".join(READERS))
    ap.add_argument("--option-count", type=int, help="mutated command lines (default: --count / 5)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    names = args.only.split(",") if args.only else READERS
    results = {}
    with tempfile.TemporaryDirectory(prefix="bench-fuzz-") as tmp:
        for name in names:
            t0 = time.perf_counter()
            directory = Path(tmp) / name
            directory.mkdir()
            count = args.count if name != "options" else (args.option_count or max(1, args.count // 5))
            per_command: dict = {}
            tally = run_reader(name, count, args.seed, directory, per_command)
            wall = time.perf_counter() - t0
            results[name] = {"inputs": tally.total, "counts": tally.counts, "failures": tally.failures,
                             "examples": tally.examples, "wall_s": wall}
            print(f"{name:>17}: {tally.total:5d} inputs, {tally.counts.get('ok', 0):5d} ok, "
                  f"{tally.counts.get('rejected', 0):5d} rejected, {tally.failures:4d} failures "
                  f"({wall:.1f} s, {_open_files()} open files)", file=sys.stderr, flush=True)
            for kind, example in tally.examples.items():
                print(f"{'':>19}{kind} x{tally.counts[kind]}: {example}", file=sys.stderr, flush=True)
            for command, sub in sorted(per_command.items()):
                results[f"{name}:{command}"] = {"inputs": sub.total, "counts": sub.counts, "failures": sub.failures,
                                                "examples": sub.examples}
                print(f"{'':>19}{command}: {sub.total} inputs, {sub.counts.get('ok', 0)} ok, "
                      f"{sub.counts.get('rejected', 0)} rejected, {sub.failures} failures", file=sys.stderr, flush=True)
    results_io.write_results("bench_fuzz", summary=__doc__.splitlines()[0], tables=[results_io.table(
        f"Fuzzed inputs per reader and command (seed {args.seed})", ["reader / command", "inputs", "ok", "rejected", "failures"],
        [[k, r["inputs"], r["counts"].get("ok", 0), r["counts"].get("rejected", 0), r["failures"]]
         for k, r in results.items()])])
    if args.json:
        print(json.dumps(results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
