"""The ``footnav`` command line."""

from __future__ import annotations

import argparse
import asyncio
import logging
import math
import sys
import uuid
from pathlib import Path

from pipeline.errors import FootnavError


def _positive(text: str) -> float:
    value = float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
    return value


def _pace(text: str) -> float:
    if text == "max":
        return math.inf
    return _positive(text.rstrip("x"))


def build_parser() -> argparse.ArgumentParser:
    from app.demo import PATHS
    from device.emulator.imu_errors import IMU_GRADES
    from pipeline.profiles import PROFILES

    parser = argparse.ArgumentParser(
        prog="footnav", description="Foot-mounted inertial navigation, live in Rerun."
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug detail to stderr")
    sub = parser.add_subparsers(dest="command", required=True)

    demo = sub.add_parser("demo", help="run everything against the built-in emulated shoe (no hardware)")
    demo.add_argument(
        "--path", choices=PATHS, default="rectangle", help="walking path (default: rectangle, 18 × 9 m)"
    )
    demo.add_argument(
        "--duration", type=_positive, default=60.0, metavar="S", help="walk duration in seconds (default 60)"
    )
    demo.add_argument(
        "--speed", type=_positive, default=1.4, metavar="M/S", help="walking speed, 1.2-1.8 m/s (default 1.4)"
    )
    demo.add_argument(
        "--grade", choices=sorted(IMU_GRADES), default="mpu6500x4", help="emulated sensor grade"
    )
    demo.add_argument("--save", type=Path, metavar="FILE.rrd", help="also write the recording to this file")
    demo.add_argument("--no-viewer", action="store_true", help="do not open a viewer (save only)")
    demo.add_argument(
        "--pace", type=_pace, default=1.0, metavar="1x|Nx|max", help="emulator speed (default real time)"
    )
    demo.add_argument("--seed", type=int, default=1, help="random seed of the emulated sensor errors")

    live = sub.add_parser("live", help="navigate a connected unit (USB serial)")
    live.add_argument("--port", required=True, help="serial port of the unit, e.g. /dev/ttyACM0")
    live.add_argument("--profile", choices=sorted(PROFILES), default="mpu6500x4", help="unit noise profile")
    live.add_argument(
        "--rate-divider",
        type=int,
        default=0,
        choices=range(7),
        metavar="K",
        help="output every 2**K samples of the 1 kHz base rate (default 0: 1 kHz)",
    )
    live.add_argument("--save", type=Path, metavar="FILE.rrd", help="also write the recording to this file")
    live.add_argument("--no-viewer", action="store_true", help="do not open a viewer (save only)")
    return parser


def _live(args: argparse.Namespace) -> int:
    from app.session import SerialSessionResult, run_serial_session
    from app.status import StatusLine
    from pipeline.navigator import NavConfig, Navigator
    from pipeline.profiles import get_profile
    from views.logger import RerunLogger
    from views.sinks import choose_sinks

    rate_hz = 1000.0 / 2**args.rate_divider
    sinks, note = choose_sinks(args.save, want_viewer=not args.no_viewer)
    print(note, file=sys.stderr)
    logger = RerunLogger(sinks, recording_id=f"live-{uuid.uuid4().hex[:12]}") if sinks else None
    navigator = Navigator(NavConfig(profile=get_profile(args.profile)), rate_hz=rate_hz)
    status = StatusLine()
    result = SerialSessionResult()
    try:
        asyncio.run(
            run_serial_session(
                args.port,
                navigator,
                [status] if logger is None else [logger.put, status],
                rate_divider_log2=args.rate_divider,
                status=status,
                result=result,
            )
        )
    except KeyboardInterrupt:
        print("\nstopped: the unit was told to stop and the recording was closed", file=sys.stderr)
    finally:
        status.finish()
        if logger is not None:
            logger.close()
    return 0


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``footnav`` console script."""
    args = build_parser().parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.WARNING, format="footnav: %(message)s"
    )
    try:
        if args.command == "demo":
            from app.demo import DemoOptions, run_demo

            return run_demo(
                DemoOptions(
                    path=args.path,
                    duration_s=args.duration,
                    speed_mps=args.speed,
                    grade=args.grade,
                    save=args.save,
                    viewer=not args.no_viewer,
                    realtime=args.pace,
                    seed=args.seed,
                )
            )
        if args.command == "live":
            return _live(args)
    except FootnavError as exc:
        print(f"footnav: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    return 2


if __name__ == "__main__":
    sys.exit(main())
