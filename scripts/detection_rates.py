#!/usr/bin/env python3
"""Detection rates of `juno diagnose`, blind, over many seeds (the figures of docs/diagnosis.md).

For every effect id and every seed: synthesize a campaign with the effect hidden at a strength
drawn uniformly from [--min-strength, --max-strength] (the fraction of the effect's documented
range, python_harness/juno/effects.py), move truth.json out of the campaign, diagnose, and
compare the named cause with the hidden one.  Prints a markdown table (detection rate, false
causes, median held-out gain, median wall time of one diagnose) and writes every case to
--json (written whole at the end, and after every case to FILE.partial so a long study can be
followed and resumed).  A partial study is resumed only by the same study: the same arguments
(the number of seeds and the workers apart) on the same code (its commit, with any uncommitted
change to the code); any other is refused, so no case of another study or another version of the
diagnosis is ever counted as this one's.  The partial file is removed once --json is written.

Run it offline, not in CI: each case costs one diagnose (30-90 s on 2 cores).

    .venv/bin/python scripts/detection_rates.py --seeds 20 --json out/detection.json

A diagnose's base fit runs on one core, so two studies side by side with one worker each (other
seeds) use a 2-core machine better than one with two; --merge tables them together:

    .venv/bin/python scripts/detection_rates.py --seeds 5 --first-seed 3000 --workers 1 --json a.json &
    .venv/bin/python scripts/detection_rates.py --seeds 5 --first-seed 3005 --workers 1 --json b.json
    .venv/bin/python scripts/detection_rates.py --merge a.json b.json --json study.json

--pair A B hides two effects together instead, each at its own strength (--pair-strengths), and
tables whether both were named and whether the first named is the stronger: the one whose
one-cause model has the larger held-out gain (each judged alone against the base model).  It also
counts the draws where the second step removed more held-out error than the first, a measure
that depends on the order (the second step is judged against the first cause's model):

    .venv/bin/python scripts/detection_rates.py --pair drivetrain_loss slip_sinkage \
        --pair-strengths 0.7 0.8 0.9 1.0 --seeds 4 --workers 1 --json pairs.json

--effects also takes the alternative forms of the catalog effects and the decoys outside it
(juno.effects.ALTERNATIVE_FORMS, DECOYS; --forms and --decoys select all of them), and --design
alt lays the campaigns out as ``juno synthesize --design alt`` does.  A second table scores them:
an alternative form is named right when the diagnosis names the catalog cause of its mechanism
(juno.effects.ALTERNATIVE_OF); a decoy when no catalog cause is named, and the table counts the
cases the diagnosis called unexplained (a result whose ``cause`` is "unexplained" or whose
``unexplained`` is true):

    .venv/bin/python scripts/detection_rates.py --forms --decoys --design alt --seeds 3 --json forms.json
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.stats import beta

# The study measures this checkout's code (and its build's FMU), whatever juno the environment
# has installed, as the other scripts do: its provenance's commit is this checkout's.
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python_harness"))

from juno.atomic import atomic_write_text  # noqa: E402
from juno.bench import commit  # noqa: E402
from juno.diagnose import diagnose  # noqa: E402
from juno.effects import ALL_EFFECTS, ALTERNATIVE_FORMS, DECOYS, EFFECT_INFO, EFFECTS  # noqa: E402
from juno.synthesize import synthesize  # noqa: E402


def one_case(effect: str | tuple[str, ...], strength: float | tuple[float, ...], seed: int, workers: int | None,
             heavy_run: bool = False, design: str = "default") -> dict:
    """Synthesize with ``effect`` hidden (a tuple: several, each at its own ``strength``) in the
    campaign ``design``, diagnose without the truth, and summarise."""
    effects = list(effect) if isinstance(effect, tuple) else [effect]
    strengths = list(strength) if isinstance(strength, tuple) else [strength]
    with tempfile.TemporaryDirectory(prefix="juno-detect-") as tmp:
        campaign = Path(tmp) / "campaign"
        synthesize(campaign, effect=effects, strength=strengths, seed=seed, heavy_run=heavy_run, design=design)
        truth = json.loads((campaign / "truth.json").read_text())
        shutil.move(str(campaign / "truth.json"), Path(tmp) / "truth.json")
        t0 = time.perf_counter()
        result = diagnose(campaign, workers=workers).to_json()
        wall = time.perf_counter() - t0
    gains = {c["name"]: c["gain"] for c in result["candidates"]}
    case = {"effect": "+".join(effects), "strength": strengths[0] if len(strengths) == 1 else strengths,
            "seed": seed, "heavy_run": heavy_run, "cause": result["cause"],
            "causes": result["causes"], "correct": judged_right(effects[0], result),
            "unexplained": said_unexplained(result),
            "gain": result["gain"]["relative"] if result["cause"] != "none" else 0.0,
            "gain_of_hidden": gains.get(effects[0]), "equally_good": result["equally_good"],
            "extension": result["extended"].get("extension", {}), "truth_extension": truth["extension"],
            "wall_time": wall,
            # every candidate's evidence, so other decision rules can be studied offline
            "candidates": [_evidence(c) for c in result["candidates"]],
            "second_round": [_evidence(c) for c in result.get("second_round", [])]}
    if design != "default":
        case["design"] = design
    info = EFFECT_INFO[effects[0]]
    case["kind"] = "catalog" if info.exact_form else ("form" if info.in_catalog else "decoy")
    if len(effects) > 1:
        # Stronger: the larger one-cause gain, each effect's model judged against the base model.
        stronger_first = sorted(effects, key=lambda e: -gains.get(e, -np.inf))
        steps = result["gain"].get("steps", [])
        case.update({"effects": effects, "gains_of_hidden": {e: gains.get(e) for e in effects},
                     "both_named": sorted(result["causes"]) == sorted(effects),
                     "correct": result["causes"] == stronger_first,
                     "removed_by_step": [s["held_out_mse_before"] - s["held_out_mse_after"] for s in steps]})
    return case


def said_unexplained(result: dict) -> bool:
    """Whether the diagnosis said the data hold something no catalog cause explains."""
    return bool(result.get("unexplained")) or result.get("cause") == "unexplained"


def judged_right(effect: str, result: dict) -> bool:
    """A catalog effect (or none) is named right when named itself; an alternative form when
    the catalog cause of its mechanism is named; a decoy when no catalog cause is named."""
    info = EFFECT_INFO[effect]
    if info.exact_form:
        return result["cause"] == effect
    if info.in_catalog:
        return result["cause"] == info.catalog_cause
    return result["cause"] not in EFFECTS or result["cause"] == "none"


def _evidence(candidate: dict) -> dict:
    """A candidate's held-out gain, z per kind of run and ablation, as the diagnosis judged it."""
    keep = ("name", "gain", "gain_by_kind", "z", "z_by_kind", "significant", "acts", "ablation", "n_params",
            "held_out_mse_before", "held_out_mse_after", "train_mse", "test_mse")
    return {k: candidate[k] for k in keep if k in candidate}


#: The confidence of the lower bounds the tables give under a rate (one-sided).
RATE_CONFIDENCE = 0.95


def rate_lower_bound(right: int, cases: int, confidence: float = RATE_CONFIDENCE) -> float:
    """The exact (Clopper-Pearson) one-sided lower confidence bound on a rate seen as ``right``
    of ``cases``: the rate below which ``right`` or more would be seen with probability at most
    1 - ``confidence``.  Why: a few draws per effect cannot show a 90 or 95 % rate (3 of 3 bound
    it only above 37 %), and the table says how far its draws do."""
    if right <= 0:
        return 0.0
    return float(beta.ppf(1.0 - confidence, right, cases - right + 1))


def _rate(right: int, cases: int) -> str:
    """``right/cases`` with its lower bound, as a table cell."""
    return f"{right}/{cases} (>= {rate_lower_bound(right, cases):.0%})"


def table(cases: list[dict]) -> str:
    """Markdown: per effect, how often the hidden cause was named, and what else was."""
    lines = []
    if any("effects" not in c and c["effect"] in EFFECTS for c in cases):
        lines += [f"| hidden effect | cases | named correctly (>= its {RATE_CONFIDENCE:.0%} lower bound) | "
                  "named instead | median held-out gain | "
                  "median diagnose wall time |", "|---|---|---|---|---|---|"]
    for effect, design in [(e, d) for e in EFFECTS for d in sorted({c.get("design", "default") for c in cases})]:
        mine = [c for c in cases if c["effect"] == effect and c.get("design", "default") == design]
        if not mine:
            continue
        right = sum(c["correct"] for c in mine)
        wrong: dict[str, int] = {}
        for c in mine:
            if not c["correct"]:
                wrong[c["cause"]] = wrong.get(c["cause"], 0) + 1
        instead = ", ".join(f"{k} {v}" for k, v in sorted(wrong.items(), key=lambda kv: -kv[1])) or "-"
        gains = [c["gain"] for c in mine if c["correct"] and effect != "none"]
        gain = f"{np.median(gains):+.1%}" if gains else "-"
        label = effect if design == "default" else f"{effect} ({design} design)"
        lines.append(f"| {label} | {len(mine)} | {_rate(right, len(mine))} | {instead} | {gain} | "
                     f"{np.median([c['wall_time'] for c in mine]):.0f} s |")
    lines += _forms_table([c for c in cases if "effects" not in c and c["effect"] not in EFFECTS], bool(lines))
    pairs = [c for c in cases if "effects" in c]
    if pairs:
        if lines:
            lines.append("")                # a blank line between the two tables
        lines += ["| hidden together | cases | both named | the stronger named first (>= its "
                  f"{RATE_CONFIDENCE:.0%} lower bound) | second step removed more | "
                  "median diagnose wall time |", "|---|---|---|---|---|---|"]
    for hidden in sorted({c["effect"] for c in pairs}):
        mine = [c for c in pairs if c["effect"] == hidden]
        reversed_steps = sum(len(r) == 2 and r[1] > r[0] for r in (c["removed_by_step"] for c in mine))
        lines.append(f"| {hidden} | {len(mine)} | {sum(c['both_named'] for c in mine)}/{len(mine)} | "
                     f"{_rate(sum(c['correct'] for c in mine), len(mine))} | {reversed_steps}/{len(mine)} | "
                     f"{np.median([c['wall_time'] for c in mine]):.0f} s |")
    return "\n".join(lines)


def _forms_table(cases: list[dict], after_table: bool) -> list[str]:
    """Markdown rows for the alternative forms and decoys (empty without such cases)."""
    if not cases:
        return []
    lines = [""] if after_table else []
    lines += [f"| hidden effect | design | cases | named right (>= its {RATE_CONFIDENCE:.0%} lower bound) | "
              "named instead | said unexplained | "
              "median diagnose wall time |", "|---|---|---|---|---|---|---|"]
    for effect in ALL_EFFECTS:
        for design in sorted({c.get("design", "default") for c in cases}):
            mine = [c for c in cases if c["effect"] == effect and c.get("design", "default") == design]
            if not mine:
                continue
            info = EFFECT_INFO[effect]
            label = f"{effect} (as {info.catalog_cause})" if info.in_catalog else f"{effect} (decoy)"
            wrong: dict[str, int] = {}
            for c in mine:
                if not c["correct"]:
                    wrong[c["cause"]] = wrong.get(c["cause"], 0) + 1
            instead = ", ".join(f"{k} {v}" for k, v in sorted(wrong.items(), key=lambda kv: -kv[1])) or "-"
            lines.append(f"| {label} | {design} | {len(mine)} | {_rate(sum(c['correct'] for c in mine), len(mine))} | "
                         f"{instead} | {sum(bool(c.get('unexplained')) for c in mine)}/{len(mine)} | "
                         f"{np.median([c['wall_time'] for c in mine]):.0f} s |")
    return lines


#: The sources whose changes change a study's cases (what its commit stands for).
CODE_PATHS = ("fmu_src", "modelDescription", "python_harness", "scripts", "CMakeLists.txt")


def study_identity(args: argparse.Namespace) -> dict:
    """What determines a study's cases: its arguments, apart from how many seeds it runs (a resumed
    study may run more), the processes a diagnose uses and where it writes; and the code's commit."""
    kept = ("effects", "forms", "decoys", "design", "first_seed", "min_strength", "max_strength", "heavy_run",
            "pair", "pair_strengths")
    return {"commit": commit(CODE_PATHS), **{k: getattr(args, k) for k in kept}}


def resumed_cases(partial: Path, identity: dict) -> list[dict]:
    """The cases of the partial study ``partial`` (none if there is no such file), provided it is
    the study ``identity`` describes; a SystemExit naming the file and what differs otherwise."""
    if not partial.exists():
        return []
    try:
        saved = json.loads(partial.read_text())
    except (OSError, ValueError) as exc:
        raise SystemExit(f"detection_rates: {partial}: not a partial study ({exc}); delete it to start afresh")
    if not isinstance(saved, dict) or "study" not in saved or "cases" not in saved:
        raise SystemExit(f"detection_rates: {partial} does not say which study it belongs to; delete it to start "
                         "afresh")
    differs = [f"{k} {saved['study'].get(k)!r} (now {v!r})" for k, v in identity.items()
               if saved["study"].get(k) != (list(v) if isinstance(v, tuple) else v)]
    if differs:
        raise SystemExit(f"detection_rates: {partial} is a partial study of another study or another version of the "
                         f"code: {'; '.join(differs)}. Run that study again to finish it, or delete the file to "
                         "start afresh")
    return list(saved["cases"])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--effects", nargs="+", choices=list(ALL_EFFECTS),
                    help="effect ids (default: the catalog's, juno.effects.EFFECTS)")
    ap.add_argument("--forms", action="store_true", help="add every alternative form of a catalog effect")
    ap.add_argument("--decoys", action="store_true", help="add every decoy outside the catalog")
    ap.add_argument("--design", choices=("default", "alt"), default="default",
                    help="campaign layout (juno synthesize --design)")
    ap.add_argument("--seeds", type=int, default=20, help="cases per effect (default 20)")
    ap.add_argument("--first-seed", type=int, default=1000)
    ap.add_argument("--min-strength", type=float, default=0.7)
    ap.add_argument("--max-strength", type=float, default=1.0)
    ap.add_argument("--workers", type=int, default=None, help="processes per diagnose (default: cores)")
    ap.add_argument("--heavy-run", action="store_true",
                    help="campaigns with a heavy drawbar run (juno synthesize --heavy-run)")
    ap.add_argument("--pair", nargs=2, metavar=("A", "B"), choices=[e for e in EFFECTS if e != "none"],
                    help="hide effects A and B together (instead of --effects one at a time)")
    ap.add_argument("--pair-strengths", nargs=4, type=float, metavar=("LO_A", "HI_A", "LO_B", "HI_B"),
                    help="--pair: each effect's strength range (default: --min-strength to --max-strength)")
    ap.add_argument("--json", metavar="FILE", help="every case, as JSON")
    ap.add_argument("--merge", nargs="+", metavar="STUDY",
                    help="run nothing: print the table of these studies' cases (--json files, finished or "
                         ".partial) together, and write them to --json as one study")
    args = ap.parse_args(argv)
    if args.heavy_run and args.design != "default":
        ap.error("--heavy-run is a variant of the default design")
    if args.merge:
        cases = []
        for path in args.merge:
            try:
                loaded = json.loads(Path(path).read_text())
                cases += loaded["cases"] if isinstance(loaded, dict) else loaded
            except (OSError, ValueError, KeyError, TypeError) as exc:
                ap.error(f"--merge {path}: not a study written by --json ({exc})")
        print(table(cases))
        if args.json:
            atomic_write_text(args.json, json.dumps({"cases": cases, "table": table(cases)}, indent=1))
        return 0
    partial = Path(args.json + ".partial") if args.json else None
    identity = study_identity(args)
    done = resumed_cases(partial, identity) if partial else []
    cases = list(done)
    if args.pair:
        if args.pair[0] == args.pair[1]:
            ap.error("--pair: two different effects")
        ranges = args.pair_strengths or [args.min_strength, args.max_strength] * 2
        if not all(0.0 < x <= 1.0 for x in ranges) or ranges[0] > ranges[1] or ranges[2] > ranges[3]:
            ap.error(f"--pair-strengths {ranges}: each range LO <= HI within (0, 1]")
        kinds = [tuple(args.pair)]
    else:
        kinds = list(args.effects or ([] if args.forms or args.decoys else EFFECTS))
        kinds += [e for e in (list(ALTERNATIVE_FORMS) if args.forms else []) + (list(DECOYS) if args.decoys else [])
                  if e not in kinds]
    # Seed-major: every effect gets its k-th case before any gets its (k+1)-th, so a study
    # stopped early still compares effects on equal footing.
    for k in range(args.seeds):
        for effect in kinds:
            seed = args.first_seed + k
            # The strength is a function of (first seed, effect, seed) only, so a resumed study
            # draws the same.
            if isinstance(effect, tuple):
                rng = np.random.default_rng([args.first_seed, 100 + list(EFFECTS).index(effect[0]),
                                             list(EFFECTS).index(effect[1]), seed])
                strength = tuple(round(float(rng.uniform(ranges[2 * i], ranges[2 * i + 1])), 3) for i in range(2))
                name = "+".join(effect)
            else:
                rng = np.random.default_rng([args.first_seed, list(ALL_EFFECTS).index(effect), seed])
                strength = 1.0 if effect == "none" else round(float(rng.uniform(args.min_strength, args.max_strength)), 3)
                name = effect
            if any(c["effect"] == name and c["seed"] == seed and c.get("design", "default") == args.design
                   for c in done):
                continue
            case = one_case(effect, strength, seed, args.workers, args.heavy_run, args.design)
            cases.append(case)
            shown = "/".join(f"{x:.3f}" for x in strength) if isinstance(strength, tuple) else f"{strength:.3f}"
            print(f"{name:16s} seed {seed} strength {shown}: named {'+'.join(case['causes']) or case['cause']:16s} "
                  f"({'right' if case['correct'] else 'WRONG'}, {case['wall_time']:.0f} s)", flush=True)
            if partial:
                atomic_write_text(partial, json.dumps({"study": identity, "cases": cases}, indent=1))
    print(table(cases))
    if args.json:
        atomic_write_text(args.json, json.dumps({"cases": cases, "table": table(cases)}, indent=1))
        if partial:
            partial.unlink(missing_ok=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
