#!/usr/bin/python3
"""Plays an NMEA log to a gpsd it starts, once, in real time: gpsfake's machinery with a clock.

usage: gps_player.py LOG PORT LINES_PER_SECOND

`gpsfake -c C` sleeps C after each line, so every line also costs its write and a turn of gpsfake's loop:
the log plays slower than real time by that overhead per line (measured here: +1 % at 2 lines a second,
+8.5 % at 20, a 10 Hz receiver's RMC and GGA). This player sends line k at k / LINES_PER_SECOND s after
the first, by the monotonic clock, so nothing accumulates. As `gpsfake -q -n -1 -P PORT`: gpsd does not
wait for a client (-n), the log is played once, and the player keeps gpsd running until it is stopped
(SIGTERM ends both). gpsfake's control socket is in $TMPDIR, as gpsfake keeps it.
"""
import sys
import time

import gps.fake as gpsfake


def main():
    if len(sys.argv) != 4:
        sys.stderr.write(__doc__)
        return 2
    log, port, rate = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
    start = None

    def pace(line, fake):
        nonlocal start
        if line >= len(fake.testload.sentences):
            time.sleep(0.1)  # played: gpsd stays up, and the session's loop does not spin
            return False
        now = time.monotonic()
        if start is None:
            start = now
        # Line k (from 0) goes out (k + 1) / rate after the start, as gpsfake -c 1/rate would send it.
        delay = start + (line + 1) / rate - now
        if delay > 0:
            time.sleep(delay)
        return True

    session = gpsfake.TestSession(options="-n", port=port, timeout=0)
    session.spawn()
    try:
        session.gps_add(log, speed=4800, pred=pace, oneshot=True)
        session.run()
    finally:
        session.cleanup()
    return 0


if __name__ == "__main__":
    sys.exit(main())
