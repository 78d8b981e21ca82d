#!/usr/bin/env python3
"""Prints the nearest-object distance once a second, and why there is none when there is
none. A starting point for robot code: a missing reading is a normal outcome (slow down
or stop), a service that cannot be reached is reported and retried.

    python3 nearest.py [--socket /run/stereod/stereod.sock] [--max-age-ms 500]
"""

import argparse
import sys
import time

from stereod import Client, ProtocolError, ServiceUnavailable


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--socket", default="/run/stereod/stereod.sock")
    parser.add_argument("--max-age-ms", type=float, default=None,
                        help="refuse readings older than this (default: the service's)")
    parser.add_argument("--count", type=int, default=0, help="stop after N lines (0: never)")
    args = parser.parse_args()

    printed = 0
    with Client(args.socket, timeout_s=2.0) as client:
        while args.count == 0 or printed < args.count:
            try:
                reading = client.distance(max_age_ms=args.max_age_ms)
            except ServiceUnavailable as error:
                # No service (not started, restarting, socket not accessible): the
                # client reconnects by itself on the next call.
                print(f"service unavailable: {error}", flush=True)
            except ProtocolError as error:
                print(f"protocol error: {error.code}: {error.message}", file=sys.stderr)
                return 1
            else:
                if reading.valid:
                    # A flagged calibration may put the number off: say so, as stereoctl does.
                    suspect = ""
                    if reading.calibration_suspect:
                        suspect = "  CALIBRATION SUSPECT"
                        if reading.calibration_row_offset_px is not None:
                            suspect += f": rows {reading.calibration_row_offset_px:+.2f} px apart"
                    # Part of the region the image's left edge keeps from seeing that near.
                    if reading.out_of_view_fraction:
                        suspect += (f"  LEFT EDGE: {100 * reading.out_of_view_fraction:.0f} % "
                                    "of the region cannot see this near")
                    print(f"frame {reading.frame}  {reading.distance_m:.3f} m  "
                          f"age {reading.age_ms:.0f} ms{suspect}", flush=True)
                elif reading.reason == "nearer_than_range":
                    print(f"obstacle nearer than {reading.nearer_than_m:.2f} m: stop", flush=True)
                else:
                    # too_few_valid_pixels, nothing_in_range, stale, source_down, ...
                    print(f"no reading: {reading.reason}: {reading.message}", flush=True)
            printed += 1
            if args.count == 0 or printed < args.count:
                time.sleep(1.0)
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except KeyboardInterrupt:
        sys.exit(0)
