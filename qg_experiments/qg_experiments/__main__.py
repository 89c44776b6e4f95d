"""Command line: ``python -m qg_experiments [--profile small] [--only ...] [--status]``.

Runs go to a pool of one process per core (``--workers`` to change), or with ``--backend ray``
to a local Ray (``--address`` joins a Ray cluster); the results are the same either way.
"""
from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

from qg_experiments.profile import load_profile
from qg_experiments.report.peg_block import peg_rows
from qg_experiments.run_archive import archive_folder
from qg_experiments.suite import EXPERIMENTS, all_specs, restore, run_suite
from qg_experiments.sweep_status import sweep_status
from qg_experiments.tasks import BACKENDS, DEFAULT_WORKERS


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m qg_experiments",
                                     description=__doc__)
    parser.add_argument("--profile", default="small", help="thesis | small | tiny "
                        "(config/experiments.yaml)")
    parser.add_argument("--only", default=",".join(EXPERIMENTS),
                        help=f"comma-separated subset of {','.join(EXPERIMENTS)}")
    parser.add_argument("--workers", type=int, default=DEFAULT_WORKERS,
                        help=f"runs at a time on this machine (default: the {DEFAULT_WORKERS} "
                        "cores)")
    parser.add_argument("--backend", choices=BACKENDS, default="process",
                        help="process: a pool on this machine; ray: Ray tasks (a local Ray "
                        "unless --address)")
    parser.add_argument("--address", default=None,
                        help="Ray cluster to run on (ray://head:10001 or head:6379; --backend ray)")
    parser.add_argument("--out", type=Path, default=Path("runs/experiments"),
                        help="results folder (a subfolder per profile)")
    parser.add_argument("--docs", type=Path, default=Path("docs"),
                        help="where results.md and figures/ go")
    parser.add_argument("--estimator", choices=("ekf", "ground_truth"), default=None,
                        help="override the profile file's wrench estimator")
    parser.add_argument("--profiles-file", type=Path, default=None)
    parser.add_argument("--config-dir", default=None,
                        help="stack config files to use (default: the repo's config/); a copy "
                        "keeps a long sweep on one set of numbers while config/ is edited")
    parser.add_argument("--report-only", action="store_true",
                        help="only regenerate results.md from saved results")
    parser.add_argument("--status", action="store_true",
                        help="say where the sweep of --only stands (saved runs, archived ones "
                        "restored first; runs under way and their episodes; the time left) and "
                        "run nothing")
    args = parser.parse_args(argv)
    if args.workers < 1:
        parser.error(f"--workers must be at least 1, got {args.workers}")
    if args.address is not None and args.backend != "ray":
        parser.error("--address needs --backend ray")
    only = tuple(o for o in args.only.split(",") if o)
    unknown = set(only) - set(EXPERIMENTS)
    if unknown:
        parser.error(f"unknown experiments {sorted(unknown)}")
    profile = load_profile(args.profile, args.profiles_file, args.estimator)
    if args.status:
        restore(profile, args.out / profile.name, archive_folder(args.docs, profile.name),
                args.config_dir)
        lines = sweep_status(all_specs(profile, only, args.config_dir),
                             args.out / profile.name, args.workers,
                             peg_rows(profile, args.docs, args.config_dir))
        print("\n".join([f"{profile.name} ({args.out / profile.name}):", *lines]))
        return
    command = "python -m qg_experiments " + shlex.join(
        sys.argv[1:] if argv is None else argv)
    path = run_suite(profile, args.out, args.docs, () if args.report_only else only,
                     args.workers, command, args.config_dir, args.backend, args.address)
    print(f"wrote {path}; TensorBoard: tensorboard --logdir "
          f"{args.out / profile.name / 'tensorboard'}")


if __name__ == "__main__":
    main()
