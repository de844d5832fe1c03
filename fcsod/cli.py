"""Command line: ``fcsod run | jobs | retry | cancel | approve | reject | audit | replay | subscribe | pki | journal |
fingers | schema``.

Exit codes: 0 success, 1 a check failed (audit, journal check), nothing
arrived in time (subscribe) or the daemon refused or did not answer a
request (retry, cancel, approve, reject), 2 bad input (config file, arguments, unreadable
record, corrupt journal, a zenoh session that cannot open, an unknown job).
"""

from __future__ import annotations

import argparse
import getpass
import json
import logging
import os
import sys
import time
from pathlib import Path

from fcso.errors import ConfigError

from .config import DaemonConfig, load_daemon_config

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_BAD_INPUT = 2

#: How often ``fcsod subscribe`` tries again to reach endpoints that do not listen yet, s.
SUBSCRIBE_RETRY_S = 0.5


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="fcsod", description="Print-server daemon: fcso on every complete print-job folder."
    )
    commands = parser.add_subparsers(dest="command", required=True)

    run = commands.add_parser("run", help="run the daemon")
    run.add_argument("--config", required=True, type=Path, help="daemon settings (fcsod.toml)")
    run.add_argument("--log-level", default="info", choices=["debug", "info", "warning", "error"])

    jobs = commands.add_parser("jobs", help="list the journal's jobs: id, folder, state, attempt, times, error")
    jobs.add_argument("--config", required=True, type=Path, help="daemon settings (state folder)")
    jobs.add_argument(
        "--state", action="append", choices=["queued", "running", "done", "failed", "held"], help="only these"
    )
    jobs.add_argument("--json", action="store_true", help="one JSON object per line instead of a table")
    for name, text in (
        ("retry", "run a failed job again (the daemon keeps the failed run's record in <output>/attempts/)"),
        ("cancel", "end a queued or running job failed, with the reason cancelled"),
        ("approve", "release a held job: place its finger into build.3mf and publish its grasps"),
        ("reject", "end a held job failed: its finger is not delivered"),
    ):
        command = commands.add_parser(name, help=text)
        command.add_argument("job", metavar="JOB", help="job id, or a prefix of exactly one job id")
        command.add_argument("--config", required=True, type=Path, help="daemon settings (state folder)")
        command.add_argument(
            "--timeout", type=float, default=60.0, metavar="S", help="wait up to S seconds for the daemon's answer"
        )

    audit = commands.add_parser("audit", help="print a job's story from its job.mcap and check its hashes")
    audit.add_argument("record", type=Path, metavar="FILE.mcap")
    audit.add_argument(
        "--verify", type=Path, metavar="DIR", help="the job's output folder: check every output file's sha256"
    )
    audit.add_argument("--inputs", type=Path, metavar="DIR", help="the job folder: check every input file's sha256")

    replay = commands.add_parser("replay", help="publish the zenoh messages recorded in a job.mcap again")
    replay.add_argument("record", type=Path, metavar="FILE.mcap")
    replay.add_argument("--config", required=True, type=Path, help="daemon settings (zenoh session)")
    replay.add_argument(
        "--listen", action="append", metavar="ENDPOINT", help="listen here instead of the config's endpoints"
    )
    replay.add_argument(
        "--connect", action="append", metavar="ENDPOINT", help="connect here instead of the config's endpoints"
    )
    replay.add_argument(
        "--wait", type=float, default=10.0, metavar="S", help="wait up to S seconds for a subscriber before publishing"
    )

    subscribe = commands.add_parser(
        "subscribe", help="print what the daemon publishes (a small cell-controller client)"
    )
    subscribe.add_argument("--config", required=True, type=Path, help="daemon settings (prefix, cell, zenoh)")
    subscribe.add_argument(
        "--connect",
        action="append",
        metavar="ENDPOINT",
        help="daemon endpoint (default: the config's connect, else its listen endpoints)",
    )
    subscribe.add_argument("--save", type=Path, metavar="DIR", help="save each received design as DIR/<job_id>.stl")
    subscribe.add_argument(
        "--no-query",
        action="store_true",
        help="do not ask the daemon for results it published earlier (asked at start and whenever the daemon "
        "reappears)",
    )
    subscribe.add_argument("--timeout", type=float, metavar="S", help="exit after S seconds")
    subscribe.add_argument("--exit-after", type=int, metavar="N", help="exit after N jobs reached done or failed")
    subscribe.add_argument(
        "--exit-after-verifications",
        type=int,
        metavar="N",
        help="exit after N verification messages (one per verified job, or per finger set of a job of several)",
    )
    subscribe.add_argument(
        "--zenoh-config",
        type=Path,
        metavar="FILE",
        help="the client's zenoh config (from fcsod pki init) instead of the daemon's",
    )
    subscribe.add_argument(
        "--verify-key",
        type=Path,
        metavar="FILE",
        help="the daemon's public key, signing.pub (default: [bus] verify_key, else signing.pub next to the signing "
        "key)",
    )

    pki = commands.add_parser("pki", help="certificates, keys and zenoh configs for the secure set-up")
    pki_commands = pki.add_subparsers(dest="pki_command", required=True)
    init = pki_commands.add_parser(
        "init", help="create a local CA, the daemon's and each cell controller's certificates and configs"
    )
    init.add_argument("directory", type=Path, metavar="DIR")
    init.add_argument("--cell", required=True, help="the [bus] cell")
    init.add_argument(
        "--client", action="append", required=True, metavar="NAME", help="a cell controller (repeat for each)"
    )
    init.add_argument("--prefix", default="fcso", help="the [bus] prefix (default fcso)")
    init.add_argument(
        "--host",
        action="append",
        metavar="NAME",
        help="name or address clients reach the daemon at (repeat; default this machine's)",
    )
    init.add_argument("--port", type=int, default=7447, help="the daemon's TLS port (default 7447)")
    init.add_argument(
        "--ros2-domain-id",
        type=int,
        metavar="N",
        help="the [ros2] domain_id when [ros2] is enabled: let its ROS 2 key expressions through",
    )
    init.add_argument(
        "--runtime-dir",
        type=Path,
        metavar="DIR",
        help="where the daemon reads its keys when running, e.g. /run/credentials/fcsod.service",
    )
    add = pki_commands.add_parser(
        "add-client",
        help="issue one more certificate from the CA (a controller or a zenoh router); not added to the access control",
    )
    add.add_argument("directory", type=Path, metavar="DIR")
    add.add_argument("name", metavar="NAME", help="the certificate's common name")
    add.add_argument(
        "--connect",
        action="append",
        required=True,
        metavar="ENDPOINT",
        help="the daemon's endpoint as this client reaches it, e.g. tls/printserver:7447",
    )
    add.add_argument(
        "--host", action="append", metavar="NAME", help="name or address this subject is reached at (a router; repeat)"
    )

    journal = commands.add_parser("journal", help="check the job journal, or rebuild it from the job records")
    journal_commands = journal.add_subparsers(dest="journal_command", required=True)
    for name, text in (
        ("check", "exit 0 when the journal is sound, 1 with the defect when not"),
        (
            "rebuild",
            "move the journal aside and rebuild it from <output>/<job_id>/job.mcap (the daemon must be stopped)",
        ),
    ):
        command = journal_commands.add_parser(name, help=text)
        command.add_argument("--config", required=True, type=Path, help="daemon settings (state and output folders)")

    fingers = commands.add_parser("fingers", help="the cell's library of delivered fingers (reused by later jobs)")
    fingers_commands = fingers.add_subparsers(dest="fingers_command", required=True)
    listing = fingers_commands.add_parser("list", help="every finger: id, parts, sha256, jobs served, retired or not")
    retire = fingers_commands.add_parser("retire", help="take a finger out of use (worn or lost): it serves no job")
    retire.add_argument("finger_id", type=int, metavar="ID")
    for command in (listing, retire):
        command.add_argument("--config", required=True, type=Path, help="daemon settings (state folder, cell)")

    schema = commands.add_parser(
        "schema", help="write the JSON Schemas of config, manifest, messages and MCAP channels"
    )
    schema.add_argument("--out", required=True, type=Path)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit code."""
    args = _parser().parse_args(argv)
    try:
        if args.command == "run":
            return _run(args)
        if args.command == "jobs":
            return _jobs(args)
        if args.command in ("retry", "cancel", "approve", "reject"):
            return _request(args)
        if args.command == "audit":
            return _audit(args)
        if args.command == "replay":
            return _replay(args)
        if args.command == "subscribe":
            return _subscribe(args)
        if args.command == "pki":
            return _pki(args)
        if args.command == "journal":
            return _journal(args)
        if args.command == "fingers":
            return _fingers(args)
        return _schema(args)
    except ConfigError as exc:
        print(f"fcsod: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except BrokenPipeError:
        # the reader stopped reading (fcsod jobs --json | head): nothing more to say, and nothing left to flush
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_OK


def _run(args: argparse.Namespace) -> int:
    import zenoh

    from .logs import setup_logging
    from .service.daemon import Daemon
    from .service.journal import JournalCorrupt
    from .storage import StateDirBusy

    config = load_daemon_config(args.config)
    setup_logging(logging.getLevelName(args.log_level.upper()))
    try:
        return Daemon(config).run()
    except (StateDirBusy, JournalCorrupt) as exc:
        print(f"fcsod: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except zenoh.ZError as exc:
        # e.g. a listen endpoint already in use or a bad zenoh config file
        print(f"fcsod: {args.config}: zenoh session cannot open: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT


def _existing_journal(config: DaemonConfig) -> Path | None:
    """The daemon's journal, or None after saying on stderr that there is none (the operator commands need it)."""
    path = config.state.dir / "journal.sqlite3"
    if path.is_file():
        return path
    print(f"fcsod: {path}: no journal (the daemon has not run with this state folder)", file=sys.stderr)
    return None


def _jobs(args: argparse.Namespace) -> int:
    from .service.journal import read_jobs

    config = load_daemon_config(args.config)
    path = _existing_journal(config)
    if path is None:
        return EXIT_BAD_INPUT
    rows = [r for r in read_jobs(path) if not args.state or r.state in args.state]
    if args.json:
        for row in rows:
            print(json.dumps(row.__dict__))
        return EXIT_OK
    print(f"{'JOB':<32} {'STATE':<8} {'RUN':>3} {'QUEUED':<20} {'FINISHED':<20} FOLDER / ERROR")
    for row in rows:
        print(
            f"{row.job_id:<32} {row.state:<8} {row.attempt:>3} {(row.queued_at or '-')[:19]:<20} "
            f"{(row.finished_at or '-')[:19]:<20} {row.folder}" + (f"\n    error: {row.error}" if row.error else "")
        )
    return EXIT_OK


def _login() -> str:
    """The login name of who runs the command (``uid <n>`` where the system knows no name for it)."""
    try:
        return getpass.getuser()
    except (KeyError, OSError):
        return f"uid {os.getuid()}"


def _request(args: argparse.Namespace) -> int:
    """``fcsod retry | cancel | approve | reject JOB``: ask the daemon through the journal's request table and print
    its answer."""
    from .bus.messages import utc_now
    from .service.journal import read_jobs, read_request, submit_request

    config = load_daemon_config(args.config)
    path = _existing_journal(config)
    if path is None:
        return EXIT_BAD_INPUT
    matches = [r.job_id for r in read_jobs(path) if r.job_id == args.job] or [
        r.job_id for r in read_jobs(path) if r.job_id.startswith(args.job)
    ]
    if len(matches) != 1:
        found = "no job" if not matches else f"{len(matches)} jobs ({', '.join(matches[:5])})"
        print(f"fcsod: {path}: {found} with the id or id prefix {args.job!r}", file=sys.stderr)
        return EXIT_BAD_INPUT
    request_id = submit_request(path, matches[0], args.command, utc_now(), _login())
    deadline = time.monotonic() + args.timeout
    while (request := read_request(path, request_id)).handled_at is None:
        if time.monotonic() > deadline:
            print(
                f"no answer from the daemon within {args.timeout:g} s (is it running?); the request stays in "
                f"{path} and is handled when the daemon runs"
            )
            return EXIT_FAILED
        time.sleep(0.1)
    print(request.outcome)
    return EXIT_OK if request.accepted else EXIT_FAILED


def _audit(args: argparse.Namespace) -> int:
    from .record.audit import audit

    if not args.record.is_file():
        print(f"fcsod: {args.record}: file not found", file=sys.stderr)
        return EXIT_BAD_INPUT
    result = audit(args.record, args.verify, args.inputs)
    for line in result.lines:
        print(line)
    for problem in result.problems:
        print(f"PROBLEM: {problem}")
    if args.verify is not None or args.inputs is not None:
        # not "verification": that word is the simulated grasp test's, whose own verdict the record tells above
        print(
            "record check " + ("FAILED" if result.problems else "passed: the files match the hashes the record holds")
        )
    return EXIT_FAILED if result.problems else EXIT_OK


def _replay(args: argparse.Namespace) -> int:
    import zenoh

    from .bus.messages import BusMessage, BusRecord, jobs_key
    from .bus.session import open_session, put
    from .bus.signing import Signer, signing_key_path
    from .record.recorder import TOPIC_BUS, read_record

    config = load_daemon_config(args.config)
    signer = Signer.from_file(signing_key_path(config))
    if not args.record.is_file():
        print(f"fcsod: {args.record}: file not found", file=sys.stderr)
        return EXIT_BAD_INPUT
    content = read_record(args.record)
    messages = [BusMessage.from_record(BusRecord.model_validate(b)) for b in content.of(TOPIC_BUS)]
    if content.truncated:
        print(f"record is truncated ({content.problem}): replaying the {len(messages)} messages before the cut")
    try:
        session = open_session(config.zenoh, listen=args.listen, connect=args.connect)
    except zenoh.ZError as exc:
        where = "--listen/--connect" if args.listen or args.connect else f"{args.config}'s [zenoh] listen"
        print(
            f"fcsod: zenoh session cannot open on {where} ({str(exc).split(' at ')[0]}): with the daemon running, "
            "replay on another endpoint: --listen tcp/127.0.0.1:<free port>, subscribers --connect there",
            file=sys.stderr,
        )
        return EXIT_BAD_INPUT
    try:
        # samples put before a subscriber has been discovered are lost: wait for one
        probe = session.declare_publisher(jobs_key(config.bus.prefix, config.bus.cell))
        deadline = time.monotonic() + args.wait
        while not probe.matching_status.matching and time.monotonic() < deadline:
            time.sleep(0.05)
        matched = probe.matching_status.matching
        probe.undeclare()
        for message in messages:
            put(session, signer.sign(message))
            print(f"replayed {message.key_expr} ({message.encoding}, {len(message.payload)} bytes)")
        # let the reliable link deliver before the session closes
        time.sleep(0.5)
    finally:
        session.close()
    if not matched:
        print("no subscriber was connected: the messages went nowhere")
        return EXIT_FAILED
    return EXIT_OK


def _subscribe(args: argparse.Namespace) -> int:
    import zenoh

    from .bus.client import Enough, configured_endpoints, nothing_listens, subscribe, subscriber_endpoints
    from .bus.session import open_session
    from .bus.signing import load_verify_key, verify_key_path
    from .config import ZenohConfig

    config = load_daemon_config(args.config)
    verify_key = load_verify_key(args.verify_key or verify_key_path(config))
    if args.zenoh_config is not None:
        if not args.zenoh_config.is_file():
            raise ConfigError(args.zenoh_config, "file not found")
        settings = ZenohConfig(config_file=args.zenoh_config, multicast_scouting=config.zenoh.multicast_scouting)
        connect = args.connect
    else:
        settings, connect = config.zenoh, subscriber_endpoints(config, args.connect)
    deadline = None if args.timeout is None else time.monotonic() + args.timeout
    waiting = False
    while True:
        try:
            # the subscriber must not bind the daemon's listen endpoints
            session = open_session(settings, listen=[], connect=connect)
            break
        except zenoh.ZError as exc:
            endpoints = ", ".join(connect or []) or f"the endpoints of {settings.config_file}"
            if "Unable to connect" not in str(exc) or not nothing_listens(connect or configured_endpoints(settings)):
                # something listens and refused the session (a certificate, an access rule): waiting will not help
                print(
                    f"fcsod: {settings.config_file or args.config}: zenoh session cannot open: {exc}", file=sys.stderr
                )
                return EXIT_BAD_INPUT
            if deadline is not None and time.monotonic() >= deadline:
                print(
                    f"fcsod: nothing listened on {endpoints} within {args.timeout:g} s: start the daemon (fcsod run) "
                    "or --connect to where it listens",
                    file=sys.stderr,
                )
                return EXIT_FAILED
            if not waiting:
                # a cell controller may start before the print server: wait for it, as zenoh peers do
                print(f"waiting for {endpoints} to listen (is the daemon running?)", file=sys.stderr, flush=True)
                waiting = True
            time.sleep(SUBSCRIBE_RETRY_S)
    enough = Enough(finished_jobs=args.exit_after, verifications=args.exit_after_verifications)
    try:
        reached = subscribe(
            session,
            config.bus.prefix,
            config.bus.cell,
            verify_key,
            enough,
            save=args.save,
            query=not args.no_query,
            timeout_seconds=None if deadline is None else max(0.0, deadline - time.monotonic()),
        )
    finally:
        session.close()
    return EXIT_FAILED if enough.bounded and not reached else EXIT_OK


def _schema(args: argparse.Namespace) -> int:
    from .schema import write_fcsod_schemas

    for path in write_fcsod_schemas(args.out):
        print(path)
    return EXIT_OK


def _pki(args: argparse.Namespace) -> int:
    from .bus.pki import add_client, config_lines, init_pki

    if args.pki_command == "add-client":
        folder = add_client(args.directory, args.name, args.connect, args.host)
        print(
            f"{folder}: certificate, key and zenoh.json5 of {args.name!r}; allow it in by adding {args.name!r} to the "
            f"cert_common_names of {Path(args.directory) / 'daemon' / 'zenoh.json5'}"
        )
        return EXIT_OK
    files = init_pki(
        args.directory,
        args.cell,
        args.client,
        prefix=args.prefix,
        hosts=args.host,
        port=args.port,
        runtime_dir=args.runtime_dir,
        ros2_domain_id=args.ros2_domain_id,
    )
    for line in config_lines(files):
        print(line)
    return EXIT_OK


def _fingers(args: argparse.Namespace) -> int:
    from .job.fingers import FingerLibrary, library_path

    config = load_daemon_config(args.config)
    path = library_path(config)
    if not path.exists():
        print(f"{path}: no finger delivered yet")
        return EXIT_OK if args.fingers_command == "list" else EXIT_BAD_INPUT
    library = FingerLibrary(path)
    try:
        if args.fingers_command == "retire":
            if not library.retire(args.finger_id):
                print(f"fcsod: {path}: no active finger {args.finger_id} (fcsod fingers list)", file=sys.stderr)
                return EXIT_BAD_INPUT
            print(f"finger {args.finger_id} retired: it serves no more jobs")
            return EXIT_OK
        for entry in library.entries(config.bus.cell):
            state = f"retired {entry.retired_at}" if entry.retired_at else "active"
            print(
                f"{entry.finger_id}: {state}, {entry.jobs}/{config.reuse.reprint_after_jobs} jobs, "
                f"sha256 {entry.sha256}, {entry.job_id}/{entry.finger_file}, parts {', '.join(entry.parts)}"
            )
    finally:
        library.close()
    return EXIT_OK


def _journal(args: argparse.Namespace) -> int:
    from .service.journal import journal_problem

    config = load_daemon_config(args.config)
    path = config.state.dir / "journal.sqlite3"
    if args.journal_command == "check":
        problem = journal_problem(path)
        if problem is not None:
            print(f"{path}: corrupt: {problem}")
            return EXIT_FAILED
        print(f"{path}: sound" if path.exists() else f"{path}: no journal yet")
        return EXIT_OK
    # a rebuild reads every job record and signs: its modules load only for it
    from .bus.signing import daemon_signer
    from .service.journal_repair import rebuild_journal
    from .storage import StateDirBusy, lock_state_dir

    config.state.dir.mkdir(parents=True, exist_ok=True)
    try:
        lock = lock_state_dir(config.state.dir)
    except StateDirBusy as exc:
        print(f"fcsod: {exc}: stop the daemon first", file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        signer, _ = daemon_signer(config)
        result = rebuild_journal(path, config.output.root, signer)
    finally:
        lock.close()
    if result.moved_aside is not None:
        print(f"old journal moved to {result.moved_aside}")
    states = sorted(result.jobs.values())
    print(
        f"rebuilt {path} from {len(result.jobs)} job records: "
        + ", ".join(f"{states.count(s)} {s}" for s in sorted(set(states)))
    )
    for job_id, why in result.skipped.items():
        print(f"skipped {job_id}: {why}")
    return EXIT_OK
