"""The ``footnav`` command line: each command's options turned into its run (the parser: ``footnav.app.parser``)."""

from __future__ import annotations

import argparse
import atexit
import difflib
import logging
import math
import os
import sys
import threading
from collections.abc import Callable
from typing import TYPE_CHECKING

from footnav.app.parser import build_parser
from footnav.pipeline.errors import FootnavError

if TYPE_CHECKING:
    from footnav.app.commands.evaluate import Reading
    from footnav.app.config import Config
    from footnav.views.lsl import LslRequest


def _lever(values: list[float] | None) -> tuple[float, float, float] | None:
    return None if values is None else (values[0], values[1], values[2])


def _lsl(args: argparse.Namespace) -> LslRequest | None:
    """``--lsl`` (and ``--lsl-wait``) as the commands take it; None without ``--lsl``."""
    if not args.lsl:
        if args.lsl_wait > 0:
            raise FootnavError("--lsl-wait applies to --lsl (how long to wait for a consumer)")
        return None
    from footnav.views.lsl import LslRequest

    return LslRequest(wait_s=args.lsl_wait)


def _export(args: argparse.Namespace) -> int:
    from footnav.app.commands.batch import scheduler_client
    from footnav.app.commands.export import run_export, run_export_batch

    options = {
        "fmt": args.format,
        "columns": args.columns,
        "profile": args.profile,
        "smooth": args.smooth,
        "stance_levels": args.stance_levels,
        "out_format": args.output_format,
    }
    if args.left or args.right or args.independent_feet or args.distance_only:
        return _export_feet(args)
    if not args.input:
        raise FootnavError("what to export? give a recording, capture or folder (INPUT), or --left FILE --right FILE")
    if len(args.input) == 1 and not args.input[0].is_dir():
        print(run_export(args.input[0], args.output, steps_out=args.steps, gait_out=args.gait, **options))
        return 0
    given = [name for name, v in (("--steps", args.steps), ("--gait", args.gait)) if v]
    if given:
        raise FootnavError(f"{' and '.join(given)}: for one recording; drop it to export a folder or several")
    with scheduler_client(args.scheduler) as client:
        lines, failures = run_export_batch(args.input, args.output, args.jobs, client, **options)
    return _report_batch(lines, failures, "exported")


def _export_feet(args: argparse.Namespace) -> int:
    from footnav.app.api.feet import export_pair

    if not (args.left or args.right):
        raise FootnavError(
            "--independent-feet and --distance-only are for --left FILE --right FILE (a two-feet capture is "
            "exported with its feet coupled as its session had them)"
        )
    if not (args.left and args.right) or args.input:
        raise FootnavError("two feet are exported as --left FILE --right FILE, without other inputs")
    if args.smooth:
        raise FootnavError(
            "--smooth and --step-smoothing apply to one foot's recording; two feet are navigated with the causal filter"
        )
    if args.jobs is not None or args.scheduler:
        raise FootnavError("--jobs and --scheduler are for a folder or several files; two feet run in this process")
    print(
        export_pair(
            args.left,
            args.right,
            args.output,
            coupling=_feet_coupling_or_default(args),
            fmt=args.format,
            columns=args.columns,
            profile=args.profile,
            stance_levels=args.stance_levels,
            steps_out=args.steps,
            gait_out=args.gait,
            out_format=args.output_format,
        )
    )
    return 0


def _report_batch(lines: list[str], failures: list[str], done: str) -> int:
    """Each file's line, each failure's (stderr), a count; 2 when any failed."""
    for line in lines:
        print(line)
    for failure in failures:
        print(f"footnav: failed: {failure}", file=sys.stderr)
    failed = f", {len(failures)} failed" if failures else ""
    print(f"{done} {len(lines)} of {len(lines) + len(failures)} files{failed}")
    return 2 if failures else 0


def _evaluate(args: argparse.Namespace) -> int:
    from footnav.app.commands.batch import scheduler_client
    from footnav.app.commands.evaluate import Reading, format_table, run_evaluate

    if args.columns:
        from footnav.device.files.recordings import CsvMapping

        CsvMapping.parse(args.columns)  # a wrong spec is told once, not once per file
    reading = Reading(args.format, args.columns, args.profile)
    if args.left or args.right or args.independent_feet or args.distance_only:
        return _evaluate_feet(args, reading)
    if not args.paths:
        raise FootnavError("evaluate needs recordings (PATH ...), or a pair of them: --left FILE --right FILE")
    with scheduler_client(args.scheduler) as client:
        rows, problems = run_evaluate(args.paths, args.smooth, args.stance_levels, args.jobs, client, reading)
    if rows:
        print(format_table(rows))
    for problem in problems:
        print(f"footnav: skipped: {problem}", file=sys.stderr)
    if not rows:
        files = "the recording could not" if len(problems) == 1 else f"none of the {len(problems)} recordings could"
        raise FootnavError(f"nothing evaluated: {files} be measured (the lines above say why)")
    return 2 if problems else 0


def _evaluate_feet(args: argparse.Namespace, reading: Reading) -> int:
    from footnav.app.commands.evaluate import evaluate_pair, format_table, pair_summary

    if not (args.left and args.right) or args.paths:
        missing = [f"--{side}" for side, path in (("left", args.left), ("right", args.right)) if path is None]
        said = f" ({' and '.join(missing)} {'is' if len(missing) == 1 else 'are'} missing)" if missing else ""
        raise FootnavError(f"two feet are evaluated as --left FILE --right FILE, without other recordings{said}")
    if args.smooth:
        raise FootnavError("--smooth applies to one foot's recording; two feet are evaluated with the causal filter")
    if args.jobs is not None or args.scheduler:
        raise FootnavError("--jobs and --scheduler are for a folder or several files; two feet run in this process")
    if args.distance_only and args.independent_feet:
        raise FootnavError("--distance-only couples the feet; --independent-feet does not: give one of them")
    rows = evaluate_pair(
        args.left,
        args.right,
        independent_only=args.independent_feet,
        heading=not args.distance_only,
        stance_levels=args.stance_levels,
        reading=reading,
    )
    print(format_table(rows))
    print(pair_summary(rows))
    return 0


def _feet_coupling_or_default(args: argparse.Namespace, two_feet: bool = True) -> str:
    """:func:`_feet_coupling`, or the default coupling when neither flag is given."""
    from footnav.pipeline.two_feet.live import DEFAULT_FEET_COUPLING

    return _feet_coupling(args, two_feet) or DEFAULT_FEET_COUPLING


def _feet_coupling(args: argparse.Namespace, two_feet: bool = True) -> str | None:
    """``--independent-feet`` / ``--distance-only`` as a ``FEET_COUPLINGS`` name (None: neither given)."""
    if args.distance_only and args.independent_feet:
        raise FootnavError("--distance-only couples the feet; --independent-feet does not: give one of them")
    given = "independent" if args.independent_feet else ("distance" if args.distance_only else None)
    if given is not None and not two_feet:
        raise FootnavError("--independent-feet and --distance-only are for two feet (--left and --right, --feet 2)")
    return given


def _config(args: argparse.Namespace) -> Config:
    """Defaults < the configuration file < the command line."""
    from footnav.app.config import CLI, load_config

    cfg = load_config(args.config)
    cfg.set("unit.profile", getattr(args, "profile", None), CLI)
    cfg.set("unit.rate_divider", getattr(args, "rate_divider", None), CLI)
    cfg.set("session.sessions_dir", str(args.sessions) if getattr(args, "sessions", None) else None, CLI)
    cfg.set("filter.step_smoothing", getattr(args, "step_smoothing", None), CLI)
    if getattr(args, "no_capture", False):
        cfg.set("session.capture", False, CLI)
    cfg.profile()  # an unknown profile name is an error now, not mid-session
    return cfg


def _live(args: argparse.Namespace, argv: list[str]) -> int:
    from footnav.app.commands.live import LiveOptions, run_live
    from footnav.pipeline.dual_imu.navigator import DEFAULT_LEVER_B_M

    one = [name for name, value in (("--port", args.port), ("--ble", args.ble)) if value is not None]
    if len(one) > 1 or (one and (args.left or args.right)):
        raise FootnavError("give one of --port or --ble (one unit), or --left/--right (two units)")
    if args.ble is not None:
        ports = {"foot": f"ble:{args.ble}"}
    elif args.port:
        ports = {"foot": args.port}
    elif args.left and args.right:
        ports = {"left": args.left, "right": args.right}
    elif args.left or args.right:
        ports = {"left": args.left} if args.left else {"right": args.right}
    else:
        raise FootnavError(
            "which unit? give --port PORT or --ble NAME, or --left PORT --right PORT for two feet "
            "(`footnav scan` lists units)"
        )
    if args.imu_mask is not None and (args.mode != "raw" or args.dual_imu):
        raise FootnavError("--imu-mask applies to --mode raw (the IMUs to stream and average)")
    if args.lever_arm is not None and not args.dual_imu:
        raise FootnavError("--lever-arm applies to --dual-imu (where IMU 2 is on the board)")
    cfg = _config(args)
    return run_live(
        LiveOptions(
            ports=ports,
            config=cfg,
            save=args.save,
            viewer=not args.no_viewer,
            web=args.web,
            keep_web=args.keep_web,
            capture=bool(cfg["session.capture"]),
            argv=("footnav", *argv),
            tof=args.tof,
            stance=args.stance,
            dual_imu_lever_b_m=(_lever(args.lever_arm) or DEFAULT_LEVER_B_M) if args.dual_imu else None,
            fused_imu_mask=(args.imu_mask or 0x0F) if args.mode == "raw" and not args.dual_imu else None,
            output=args.mode,
            model=args.unit,
            lsl=_lsl(args),
            feet_coupling=_feet_coupling_or_default(args, two_feet=len(ports) == 2),
        )
    )


def _calibrate(args: argparse.Namespace) -> int:
    from footnav.app.commands.calibrate import CalibrateOptions, run_calibrate
    from footnav.app.session import UnitAddress

    cfg = _config(args)
    address = None
    if args.port:
        address = UnitAddress.parse(args.port)
    elif args.ble is not None:
        address = UnitAddress("ble", args.ble or None)
    return run_calibrate(
        CalibrateOptions(
            config=cfg,
            address=address,
            capture_file=args.capture,
            demo=args.demo,
            imu_mask=args.imu_mask,
            rate_divider_log2=args.rate_divider,
            hold_s=args.hold,
            allow_no_temperature=args.no_temperature,
            capture=bool(cfg["session.capture"]),
            demo_pace=args.pace,
        )
    )


def _scan(args: argparse.Namespace) -> int:
    """Serial ports and BLE units that look like shoe units; without Bluetooth, one line says so."""
    import asyncio

    from footnav.device.discovery import scan

    report = asyncio.run(scan(args.timeout))
    for line in report.lines():
        print(line)
    return 0


def _replay(args: argparse.Namespace) -> int:
    from footnav.device.files.capture_schema import starts_like_capture

    is_capture = starts_like_capture(args.file)
    if is_capture is None:  # unreadable: the command says what is wrong with it
        is_capture = args.file.suffix.lower() == ".mcap"
    return _replay_capture(args) if is_capture else _replay_recording(args)


def _only_for(args: argparse.Namespace, given: dict[str, bool], what: str) -> None:
    """Refuse the options in ``given`` (name -> given) that do not apply to ``what``."""
    wrong = [name for name, is_given in given.items() if is_given]
    if wrong:
        verb = "does" if len(wrong) == 1 else "do"
        raise FootnavError(f"{args.file} is {what}: {', '.join(wrong)} {verb} not apply to it")


def _replay_capture(args: argparse.Namespace) -> int:
    from footnav.app.commands.replay import ReplayOptions, run_replay

    recording_only = {
        "--format": args.format is not None,
        "--columns": args.columns is not None,
        "--smooth": args.smooth,
        "--no-stance-levels": not args.stance_levels,
    }
    _only_for(args, recording_only, "a footnav capture, replayed with the settings it was recorded with")
    if args.end <= args.start:
        raise FootnavError(f"--end ({args.end:g} s) must come after --start ({args.start:g} s)")
    cfg = _config(args)
    return run_replay(
        ReplayOptions(
            path=args.file,
            config=cfg,
            speed=args.speed,
            start_s=args.start,
            end_s=args.end,
            save=args.save,
            viewer=not args.no_viewer,
            web=args.web,
            keep_web=args.keep_web,
            config_is_explicit=args.config is not None or args.profile is not None,
            tof=not args.without_tof,
            stance=args.stance,
            lsl=_lsl(args),
            feet_coupling=_feet_coupling(args),
        )
    )


def _replay_recording(args: argparse.Namespace) -> int:
    from footnav.app.commands.replay_recording import RecordingReplayOptions, run_recording_replay

    capture_only = {
        "--speed": not math.isinf(args.speed),
        "--start": args.start > 0,
        "--end": not math.isinf(args.end),
        "--without-tof": args.without_tof,
        "--stance": args.stance is not None,
        "--config": args.config is not None,
        "--independent-feet": args.independent_feet,
        "--distance-only": args.distance_only,
    }
    _only_for(args, capture_only, "a recording from another tool, navigated whole")
    if args.smooth and args.step_smoothing:
        raise FootnavError("--smooth and --step-smoothing: choose one")
    smooth = "whole" if args.smooth else ("step" if args.step_smoothing else None)
    return run_recording_replay(
        RecordingReplayOptions(
            path=args.file,
            fmt=args.format,
            columns=args.columns,
            profile=args.profile,
            smooth=smooth,
            stance_levels=args.stance_levels,
            save=args.save,
            viewer=not args.no_viewer,
            web=args.web,
            keep_web=args.keep_web,
            lsl=_lsl(args),
        )
    )


def _show_config(args: argparse.Namespace) -> int:
    cfg = _config(args)
    where = f"file {cfg.file}" if cfg.file else "no configuration file (looked for ./footnav.toml)"
    print(f"# effective footnav configuration; {where}")
    for line in cfg.lines():
        print(line)
    return 0


def _demo(args: argparse.Namespace) -> int:
    from footnav.app.commands.demo import DemoOptions, run_demo
    from footnav.device.models import unit_model

    cfg = _config(args)
    return run_demo(
        DemoOptions(
            path=args.path,
            duration_s=args.duration,
            speed_mps=args.speed,
            grade=args.grade or ("icm20948" if args.dual_imu else unit_model(args.unit or "oblu").imu),
            axes=args.axis_errors or ("gyro-bias-calibrated" if args.tof and not args.miscalibrated else "none"),
            save=args.save,
            viewer=not args.no_viewer,
            realtime=args.pace,
            seed=args.seed,
            feet=args.feet,
            web=args.web,
            keep_web=args.keep_web,
            capture=bool(cfg["session.capture"]),
            config=cfg,
            miscalibrated=args.miscalibrated,
            dual_imu=args.dual_imu,
            lever_b_m=_lever(args.lever_arm),
            board_lever_b_m=_lever(args.board_lever_arm),
            tof=args.tof,
            stance=args.stance,
            unit=args.unit,
            mode=args.mode,
            imu_mask=args.imu_mask,
            lsl=_lsl(args),
            feet_coupling=_feet_coupling_or_default(args, two_feet=args.feet == 2),
        )
    )


def _experiment(args: argparse.Namespace) -> int:
    from footnav.app.experiments import experiment_parser, run_experiment

    return run_experiment(experiment_parser(args.experiment_argv).parse_args(args.experiment_argv))


def _recordings_whole(code: int) -> int:
    """``code``, or 3 when the command's session ran but a .rrd file it wrote stopped early (a full
    disk; ``footnav.views.outputs.INCOMPLETE_RECORDINGS``, said when it happened)."""
    outputs = sys.modules.get("footnav.views.outputs")  # loaded only if a session had Rerun outputs
    if code == 0 and outputs is not None and outputs.INCOMPLETE_RECORDINGS:
        return int(outputs.EXIT_RECORDING_INCOMPLETE)
    return code


def main(argv: list[str] | None = None) -> int:
    """The ``footnav`` command line on ``argv`` (default ``sys.argv[1:]``); returns the exit code."""
    argv = sys.argv[1:] if argv is None else argv
    args = _parse(argv)
    return _run_command(args, argv)


def run() -> None:
    """Entry point of the ``footnav`` console script (and ``python -m footnav.app``): :func:`main`, then exit.

    Linear algebra runs on one thread (``OPENBLAS_NUM_THREADS=1`` unless set, before numpy loads OpenBLAS; the
    workers of ``--jobs`` inherit it). After a command that writes only plain files (:data:`PLAIN_FILE_COMMANDS`)
    with no other thread left, the process runs its exit handlers, flushes its streams and ends (``os._exit``)
    without the interpreter's teardown of numba's and LLVM's objects, which takes longer than navigating a
    10-minute walk. Numba loads without its cffi support (``FOOTNAV_NUMBA_CFFI=0``, see
    :mod:`footnav.pipeline.jit`). Why: design page "Architecture", "A command's start and end".
    """
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    os.environ.setdefault("FOOTNAV_NUMBA_CFFI", "0")
    argv = sys.argv[1:]
    args = _parse(argv)
    code = _run_command(args, argv)
    if args.command in PLAIN_FILE_COMMANDS and threading.active_count() == 1:
        atexit._run_exitfuncs()
        try:
            for stream in (sys.stdout, sys.stderr):
                if stream is not None:  # None: started with that descriptor closed
                    stream.flush()
        except (OSError, ValueError):  # a full disk, a closed pipe: the interpreter says so and exits with 120
            sys.exit(code)
        os._exit(code)
    sys.exit(code)


PLAIN_FILE_COMMANDS = frozenset({"export", "evaluate", "config"})
"""Commands whose outputs are files closed before they return: no Rerun stream, capture or outlet is left to
the interpreter's teardown."""


def _parse(argv: list[str]) -> argparse.Namespace:
    """``argv`` parsed (``parser.error`` exits with 2 on bad options)."""
    parser = build_parser()
    args, rest = parser.parse_known_args(argv)
    if args.command == "experiment":  # its own parser, built when it runs
        args.experiment_argv = rest
    elif rest:
        _command_parser(parser, args.command).error(_unrecognized(parser, args.command, rest))
    if getattr(args, "keep_web", False) and not args.web:
        parser.error("--keep-web keeps the web viewer of --web: give --web too")
    return args


def _command_parser(parser: argparse.ArgumentParser, command: str) -> argparse.ArgumentParser:
    """The sub-parser of ``command`` (its usage goes with an error in its options)."""
    (commands,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    found: argparse.ArgumentParser = commands.choices[command]
    return found


def _unrecognized(parser: argparse.ArgumentParser, command: str, rest: list[str]) -> str:
    """The error for arguments ``command`` does not take, with the closest option to each unknown one."""
    options = [o for a in _command_parser(parser, command)._actions for o in a.option_strings]
    hints = []
    for arg in rest:
        if arg.startswith("-"):
            close = difflib.get_close_matches(arg.split("=", 1)[0], options, n=1, cutoff=0.75)
            hints += [f"{arg.split('=', 1)[0]}: did you mean {close[0]}?"] if close else []
    return f"unrecognized arguments: {' '.join(rest)}" + "".join(f"; {h}" for h in hints)


def _run_command(args: argparse.Namespace, argv: list[str]) -> int:
    """Run the parsed command; returns its exit code (2 with a :class:`FootnavError`, said on stderr)."""
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING, format="footnav: %(message)s")
    if not args.verbose:  # sessions report link events themselves (terminal, recording, capture)
        logging.getLogger("footnav.device.links.reconnecting").setLevel(logging.ERROR)
    commands: dict[str, Callable[[argparse.Namespace], int]] = {
        "demo": _demo,
        "live": lambda a: _live(a, argv),
        "scan": _scan,
        "calibrate": _calibrate,
        "replay": _replay,
        "config": _show_config,
        "export": _export,
        "evaluate": _evaluate,
        "experiment": _experiment,
    }
    try:
        if getattr(args, "save", None) is not None:  # before anything starts (demo, live, replay)
            from footnav.views.outputs import check_save_destination

            check_save_destination(args.save)
        return _recordings_whole(commands[args.command](args))
    except FootnavError as exc:
        print(f"footnav: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    run()
