"""The peg's sections of ``docs/results.md`` (5 and 6) written again alone, from the runs saved
so far and the episode rows beside the page (``report.peg_block``): a thesis-budget peg sweep
spans sessions, and its section can show where it stands without the page's other experiments
being run again. The archived runs of the profile are restored into the runs' folder first.

Usage: python -m qg_experiments.peg_report [--profile thesis] [--profiles-file F]
       [--out runs/experiments] [--docs docs] [--config-dir D]
"""
from __future__ import annotations

import argparse
from pathlib import Path

from qg_experiments.profile import Profile, load_profile
from qg_experiments.report.markdown import PEG_BLOCK, write_marked_block
from qg_experiments.report.peg_block import PEG_EXPERIMENTS, peg_block, peg_specs_of
from qg_experiments.run_archive import archive_folder
from qg_experiments.tasks import restore_archived

__all__ = ["write_section", "main"]


def write_section(profile: Profile, out: Path, docs: Path, config_dir: str | None = None
                  ) -> Path:
    """Restore the profile's archived peg runs into ``out`` (a subfolder per profile), then
    put the peg's block into ``docs/results.md`` in place of the old one; returns the page."""
    out = Path(out) / profile.name
    specs = [spec for experiment in PEG_EXPERIMENTS
             for group in peg_specs_of(profile, experiment, config_dir) for spec in group]
    restore_archived(specs, out, archive_folder(Path(docs), profile.name))
    page = Path(docs) / "results.md"
    write_marked_block(page, *PEG_BLOCK,
                       "\n".join(peg_block(profile, out, Path(docs), config_dir)))
    return page


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m qg_experiments.peg_report",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--profile", default="thesis")
    parser.add_argument("--profiles-file", type=Path, default=None)
    parser.add_argument("--out", type=Path, default=Path("runs/experiments"))
    parser.add_argument("--docs", type=Path, default=Path("docs"))
    parser.add_argument("--config-dir", default=None)
    args = parser.parse_args(argv)
    page = args.docs / "results.md"
    if not page.is_file() or not all(marker in page.read_text() for marker in PEG_BLOCK):
        parser.error(f"no peg sections between markers in {page}: write the whole page once "
                     f"(python -m qg_experiments --profile {args.profile} --report-only)")
    try:
        profile = load_profile(args.profile, args.profiles_file)
    except (OSError, ValueError) as error:
        parser.error(str(error))
    print(f"wrote the peg's sections of "
          f"{write_section(profile, args.out, args.docs, args.config_dir)}")


if __name__ == "__main__":
    main()
