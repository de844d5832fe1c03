"""Command line of the verification: ``fcso verify DIR`` and ``fcso design --verify / --verify-top K``."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from .verify_config import DEFAULT_TOP_K

if TYPE_CHECKING:
    from .sim.report import VerificationReport
    from .verify_config import VerifyConfig

# the parser's options need nothing of the simulation: each command imports it when it runs (fcso.cli)

#: ``fcso verify`` and ``fcso design --verify``: the design was verified and written, and did not pass (1: a failed
#: design, 2: bad input).
EXIT_NOT_VERIFIED = 3


def add_verify_command(commands) -> None:
    """The ``verify`` subcommand."""
    run = commands.add_parser("verify", help="precision and holding tests of a finished design in simulation (MuJoCo)")
    run.add_argument("directory", type=Path, metavar="DIR", help="output folder of fcso design")
    run.add_argument("--config", type=Path, help="settings (TOML, its [verify] table)")
    add_settings_options(run)
    run.add_argument("--quiet", action="store_true", help="no progress and no summary")


def add_settings_options(parser) -> None:
    """Options shared by ``verify`` and ``design --verify``."""
    parser.add_argument("--trials", type=int, metavar="N", help="precision trials per scenario (verify.trials)")
    parser.add_argument("--verify-seed", type=int, metavar="N", help="seed of the trial perturbations (verify.seed)")
    parser.add_argument(
        "--simulate-again",
        action="store_true",
        help="simulate every grasp and push, even those simulated before (verify.reuse_simulations = false)",
    )


def add_design_options(parser) -> None:
    """``--verify`` and ``--verify-top`` of ``fcso design``."""
    parser.add_argument(
        "--verify",
        action="store_true",
        help=f"verify in simulation as the last stage, choosing among the {DEFAULT_TOP_K} best candidates as the "
        "daemon does (--verify-top sets how many)",
    )
    parser.add_argument(
        "--verify-top",
        type=int,
        default=None,
        metavar="K",
        help=f"verify up to K candidates in the order of the measure and deliver the first that passes (implies "
        f"--verify; default {DEFAULT_TOP_K}, the daemon's [verify] top_k; 0: verify the design's own choice only)",
    )


def settings(args) -> VerifyConfig:
    """The ``[verify]`` settings of ``--config`` with the command line's overrides."""
    from .sim.config import load_verify_config

    config = load_verify_config(getattr(args, "config", None))
    overrides = {}
    if getattr(args, "trials", None) is not None:
        overrides["trials"] = args.trials
    if getattr(args, "verify_seed", None) is not None:
        overrides["seed"] = args.verify_seed
    if getattr(args, "simulate_again", False):
        overrides["reuse_simulations"] = False
    return config.model_copy(update=overrides) if overrides else config


def run_verify(args, progress) -> int:
    """``fcso verify DIR``: write verification.json and the report section; print a summary."""
    from .output.verification_page import load_design, write_verification
    from .sim.config import with_print_density
    from .sim.verify import verify_delivered

    report, design = load_design(args.directory)
    config = with_print_density(settings(args), report.settings)
    try:
        verification = verify_delivered(design, config, progress)
    finally:
        progress.close()
    write_verification(args.directory, verification, design)
    if not args.quiet:
        print(summary(verification))
        print(f"wrote {args.directory}/verification.json and the verification section of report.html")
    return verdict_exit(verification, args.quiet)


def verdict_exit(verification: VerificationReport, quiet: bool) -> int:
    """Print the verdict as the last line (unless ``quiet``); the exit code: 0 when the design passed, else
    :data:`EXIT_NOT_VERIFIED`."""
    from .sim.report import verdict_text

    if not quiet:
        print(verdict_text(verification))
    return 0 if verification.passed else EXIT_NOT_VERIFIED


def summary(verification: VerificationReport) -> str:
    """The verdict, then a few lines per scenario: success rates, median errors and holding forces, designed against
    flat."""
    from .sim.report import reused_note, verdict_text

    lines = [verdict_text(verification)]
    for s in verification.scenarios:
        stopped = "" if s.stopped_after_trials is None else f" (trials stopped after {s.stopped_after_trials})"
        lines.append(f"{s.part} pose {s.pose_index}:{stopped}")
        for name, r in (("designed", s.fcso), ("flat", s.flat)):
            holding = " ".join(f"{d} {'held' if v is None else f'{v:.1f}'}" for d, v in r.holding_n.items())
            median = "-" if r.median_error_mm is None else f"{r.median_error_mm:.3f} mm {r.median_error_deg:.2f} deg"
            lines.append(
                f"  {name:<9} success {r.success_rate:4.0%} of {len(r.trials)}  median error {median}  "
                f"holding N: {holding or 'not tested'}"
            )
    lines.append(f"verification {'passed' if verification.passed else 'did not pass'}")
    if reused := reused_note(verification):
        lines.append(reused)
    lines.extend(f"warning: {w}" for w in verification.warnings)
    return "\n".join(lines)


def verify_job_outputs(job, args, progress_line) -> int:
    """``fcso design --verify`` / ``--verify-top K``: verify every finger set's finger (one or several), each choosing
    among its K best candidates and its other pad sizes' (:func:`fcso.sim.choose.verify_top`); when a choice delivers
    another finger, the job is written into ``--out`` again with the sets' report and pick plan following it; then each
    verification into its set's folder.

    Parameters
    ----------
    job : SetsResult
        The job as designed and written into ``args.out``.
    args : argparse.Namespace
    progress_line : callable
        A new progress display per set.

    Returns
    -------
    int
        The exit code: the worst of the sets' (:data:`EXIT_NOT_VERIFIED` when one did not pass).
    """
    from .layout import set_folder
    from .output.files import write_set_outputs
    from .output.verification_page import ranking_html, write_verification
    from .sim.choose import verify_top
    from .sim.config import with_print_density
    from .sim.verify import design_under_test, verify_delivered

    top = DEFAULT_TOP_K if args.verify_top is None else args.verify_top
    verified, chosen_again = [], False
    for number, result in enumerate(job.designs, start=1):
        config = with_print_density(settings(args), result.report.settings)
        progress = progress_line()
        try:
            if top > 0:
                chosen, verification, design, ranking = verify_top(result, top, config, progress)
                if chosen is not result:
                    job, chosen_again = job.delivered(number, chosen, verification.choice), True
                extra = ranking_html(ranking, verification.choice)
            else:
                design = design_under_test(result)
                verification, extra = verify_delivered(design, config, progress), ""
        finally:
            progress.close()
        verified.append((verification, design, extra))
    if chosen_again:
        # report.json, the pick plan, the fingers and the pictures follow the newly chosen candidates
        write_set_outputs(job, args.out)
    codes = [0]
    for number, (verification, design, extra) in enumerate(verified, start=1):
        out = args.out / set_folder(number, job.several)
        write_verification(out, verification, design, extra)
        if not args.quiet:
            print(summary(verification))
            if verification.choice:
                print(f"delivered {verification.choice}")
            print(f"wrote {out}/verification.json and the verification section of report.html")
        codes.append(verdict_exit(verification, args.quiet))
    return max(codes)


def restore_section(directory: Path) -> None:
    """After ``fcso report`` rebuilt report.html: put the verification section back when verification.json exists."""
    from .output.verification_page import (
        load_design,
        ranking_html,
        read_verification,
        section_html,
        verification_pictures,
        write_section,
    )

    verification = read_verification(directory)
    if verification is None:
        return
    _, design = load_design(directory)
    extra = ranking_html(verification.ranking or [], verification.choice)
    write_section(
        Path(directory) / "report.html", section_html(verification, verification_pictures(verification, design), extra)
    )
