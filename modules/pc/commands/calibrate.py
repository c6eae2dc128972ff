"""``tokenring calibrate LOG...``: the floor's mean step scale pooled over earlier drives' data
logs (:mod:`modules.pc.calibration`), for a later drive to start from."""

from __future__ import annotations

import argparse

HELP = "the floor's step scale learnt by earlier drives (odometry calibration from data logs)"

EXAMPLES = """\
examples:
  tokenring calibrate logs/localization-*.trlog
  tokenring calibrate logs/localization-*.trlog --json
  then, in config/localization.yaml (or --set for bench.drivesim):
    filter: {initial: {step_scale: 1.0098, step_scale_mean_sigma: 0.002}}
"""

#: the least σ a calibration is given in the configuration it suggests: the filter lets the floor's
#: mean walk by 0.001 per move (filter.noise.step_scale_mean_walk_per_move), and floors differ
LEAST_SUGGESTED_SIGMA = 0.002


def add_parser(sub: argparse._SubParsersAction) -> None:
    from tokenring.cli import add_json_option, with_examples

    p = sub.add_parser(
        "calibrate",
        help=HELP,
        description="Pool the floor's mean step scale that the localisation filter learnt in earlier "
        "drives (their data logs, .trlog) into one calibration for later drives to start from. Drives "
        "that never had a wall ahead or behind in sonar range on a straight leg learnt nothing and are "
        "left out; the pooled σ is widened where the drives disagree more than their σ say.",
        **with_examples(EXAMPLES),
    )
    p.add_argument("logs", nargs="+", metavar="LOG", help="localisation data logs (.trlog)")
    add_json_option(p)


def run(args: argparse.Namespace) -> int:
    from modules.pc.calibration import calibrate_logs
    from tokenring.cli import print_json

    found, mm_per_step = calibrate_logs(args.logs)
    suggested_sigma = max(found.sigma, LEAST_SUGGESTED_SIGMA)
    if args.json:
        print_json({**found.as_dict(), "mm_per_step": mm_per_step, "suggested_sigma": suggested_sigma})
        return 0
    print(
        f"floor step scale {found.step_scale:.4f} ± {found.sigma:.4f} (true step "
        f"{mm_per_step * found.step_scale:.4f} mm against the nominal {mm_per_step} mm) from "
        f"{len(found.used)} of {len(found.used) + len(found.skipped)} logs; Birge ratio {found.birge_ratio:.2f}"
    )
    for name, why in found.skipped.items():
        print(f"  left out {name}: {why}")
    print("to start later drives from it, in config/localization.yaml:")
    print(
        f"  filter: {{initial: {{step_scale: {found.step_scale:.4f}, "
        f"step_scale_mean_sigma: {suggested_sigma:.4f}}}}}"
    )
    return 0
