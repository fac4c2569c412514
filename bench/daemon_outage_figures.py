#!/usr/bin/python3
"""The outage figures of one drive of bench/daemon_outages.sh: gearpulsed's outage distance against the
distance driven over its own outage, and `gearpulse replay`'s on the same signals over its own.

While the drive plays it polls `gearpulsectl status --json` every 0.1 s into WORK/polls.csv, keeping the
model on disk where GPS is lost; the daemon's outage distance is the pulse count between the polls where
it lost GPS and had it back (as tests/daemon/e2e_test.cpp takes it). After the drive it runs `gearpulse
track` on the drive's audio and `gearpulse replay` with that model on the tracked frequency and the fixes,
each fix given once (as the daemon measures it; and, for comparison, held on every row of the GPS
timeout as tests/daemon/e2e_test.cpp holds it). Prints one `figure` line per figure and writes
WORK/figures.json. With --offline, the figures of a finished drive from its polls.csv.
"""
import argparse
import bisect
import csv
import io
import json
import os
import shutil
import subprocess
import sys
import time

# The demo's monitor polls and reads the truth the same way.
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "scripts", "lib"))
from monitor import alive, at, status  # noqa: E402


def load_truth(path):
    ts, speeds, gears, freqs = [], [], [], []
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            ts.append(float(row["t"]))
            speeds.append(float(row["speed"]))
            gears.append(int(row["gear"]))
            freqs.append(float(row["freq"]))
    return ts, speeds, gears, freqs


def driven(truth, a, b):
    """The true distance (m) between drive times a and b, trapezoidal over truth.csv."""
    ts, vs = truth[0], truth[1]
    d = 0.0
    for i in range(1, len(ts)):
        lo, hi = max(ts[i - 1], a), min(ts[i], b)
        if hi > lo:
            d += 0.5 * (vs[i] + vs[i - 1]) * (hi - lo)
    return d


def nmea_fixes(path):
    """(drive time, speed m/s) of every valid RMC; the drive's t = 0 is 12:00:00 UTC (gearpulse simulate)."""
    fixes = []
    with open(path) as f:
        for line in f:
            cells = line.strip().split(",")
            if not cells[0] == "$GPRMC" or len(cells) < 8 or cells[2] != "A" or not cells[7]:
                continue
            hms = float(cells[1])
            tod = (hms // 10000) * 3600 + ((hms % 10000) // 100) * 60 + hms % 100
            fixes.append((tod - 12 * 3600, float(cells[7]) * 1852.0 / 3600.0))
    return fixes


def replay_outage(work, cli, model, outage, gps_timeout, held):
    """`gearpulse replay` on the tracked audio and the drive's fixes: (distance, from, to) of its outage.

    held: every fix repeated on the rows of the daemon's GPS timeout after it (tests/daemon/e2e_test.cpp):
    replay measures a speed on every row it is given, so a fix is measured at every row it is held on;
    the outage is then from the first row without GPS to the first row with it again. Otherwise each fix
    on its own row only, measured once as the daemon measures it, and the outage from the last fix before
    it plus the GPS timeout (when the daemon loses GPS) to the first fix after it.
    """
    drive = os.path.join(work, "drive")
    track = subprocess.run([cli, "track", os.path.join(drive, "drive.wav")], capture_output=True, text=True,
                           check=True).stdout
    fixes = nmea_fixes(os.path.join(drive, "drive.nmea"))
    merged = os.path.join(work, "replay-input-held.csv" if held else "replay-input.csv")
    with open(merged, "w") as out:
        out.write("t,speed,freq\n")
        nxt, fix_t, fix_v, given = 0, -1e9, 0.0, True
        for row in list(csv.reader(io.StringIO(track)))[1:]:
            t = float(row[0])
            while nxt < len(fixes) and fixes[nxt][0] <= t + 1e-9:
                fix_t, fix_v, given = fixes[nxt][0], fixes[nxt][1], False
                nxt += 1
            speed = fix_v if (t - fix_t <= gps_timeout if held else not given) else ""
            given = True
            out.write(f"{row[0]},{speed},{row[1]}\n")
    # --band-low: the daemon's tracker.band_low (its default, which the harness' config leaves), the low end
    # of `track`'s default band above: what the readings can show.
    rows = subprocess.run([cli, "replay", "--band-low", "50", "--model", model, merged], capture_output=True,
                          text=True, check=True).stdout
    with open(os.path.join(work, "replay-held.csv" if held else "replay.csv"), "w") as f:
        f.write(rows)
    start, end = outage
    last_fix = max(t for t, _ in fixes if t < start)
    back_fix = min(t for t, _ in fixes if t >= start + end)
    distance, began, last_t, last_v = 0.0, None, 0.0, 0.0
    for row in list(csv.reader(io.StringIO(rows)))[1:]:
        t, v, source = float(row[0]), float(row[1]), row[3]
        if began is not None:
            distance += last_v * (t - last_t)
            if (source == "gps") if held else (t >= back_fix - 1e-9):
                return distance, began, t
        elif (t > start - 5 and source != "gps") if held else (t > last_fix + gps_timeout):
            began = t
        last_t, last_v = t, v
    return None


def poll(a, truth, t0, out_start, model):
    """Every status while the drive plays, to WORK/polls.csv; the model on disk where GPS is lost."""
    sock = os.path.join(a.work, "control.sock")
    shutil.copy(os.path.join(a.work, "state", "model.json"), model)
    lost = False
    with open(os.path.join(a.work, "polls.csv"), "w") as polls:
        polls.write("t,source,gear,speed,true_speed,true_gear,pulses,track_freq,true_freq,late_hops\n")
        while alive(a.until_pid):
            s = status(a.ctl, sock)
            t = time.time() - t0
            if s is not None:
                source = s.get("source", "?")
                i = max(0, bisect.bisect_right(truth[0], t) - 1)
                polls.write(f"{t:.2f},{source},{s.get('gear', 0)},{s.get('speed') or 0.0:.3f},"
                            f"{truth[1][i]:.3f},{truth[2][i]},{s.get('pulses', 0)},"
                            f"{s.get('tracker', {}).get('freq') or ''},{truth[3][i]:.2f},"
                            f"{s.get('tracker', {}).get('late_hops', '')}\n")
                if not lost and t > out_start - 5 and source != "gps":
                    lost = True
                    shutil.copy(os.path.join(a.work, "state", "model.json"), model)
            time.sleep(0.1)
    time.sleep(1.5)  # let the reader drain the PTY


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--work", required=True)
    ap.add_argument("--ctl", required=True)
    ap.add_argument("--cli", required=True, help="the gearpulse binary (track, replay)")
    ap.add_argument("--ppk", type=float, required=True)
    ap.add_argument("--outage", required=True, help="START:LEN of the drive's outage (s)")
    ap.add_argument("--until-pid", type=int, required=True, help="the feeder: the drive ends when it exits")
    ap.add_argument("--label", required=True, help="the drive's name on the figure lines")
    ap.add_argument("--gps-timeout", type=float, default=1.5, help="the daemon's gps.timeout (s)")
    ap.add_argument("--offline", action="store_true", help="figures from a finished drive's polls.csv")
    a = ap.parse_args()

    work = a.work
    truth = load_truth(os.path.join(work, "drive", "truth.csv"))
    # The drive's t = 0: when the harness started the audio (scripts/lib/harness.sh, hs_start_audio).
    t0 = float(open(os.path.join(work, "drive.t0")).read())
    out_start, out_len = (float(x) for x in a.outage.split(":"))
    model = os.path.join(work, "model-at-loss.json")
    if not a.offline:
        poll(a, truth, t0, out_start, model)

    lost = back = None  # (drive time, pulses)
    edge_gap, last_poll = 0.0, 0.0
    late_hops = ""  # hops the daemon stepped after a backlog, on the GPS of their due time (the last poll's)
    with open(os.path.join(work, "polls.csv"), newline="") as f:
        for row in csv.DictReader(f):
            t, source, pulses = float(row["t"]), row["source"], int(row["pulses"])
            late_hops = row.get("late_hops") or late_hops
            if lost is None and t > out_start - 5 and source != "gps":
                lost, edge_gap = (t, pulses), max(edge_gap, t - last_poll)
            elif lost is not None and back is None and source == "gps":
                back, edge_gap = (t, pulses), max(edge_gap, t - last_poll)
            last_poll = t

    def pct(x, ref):

        return 100.0 * (x / ref - 1.0)

    figures = {"truth_outage_m": driven(truth, out_start, out_start + out_len)}
    if lost is None or back is None:
        print(f"{a.label}: the daemon's outage was not seen (lost {lost}, back {back})")
    else:
        live = (back[1] - lost[1]) / a.ppk * 1000.0
        live_truth = driven(truth, lost[0], back[0])
        # What the car covers between two polls at the daemon's edges and a tracker hop or two of lag.
        edges = (edge_gap + 0.3) * (at(truth[0], truth[1], lost[0]) + at(truth[0], truth[1], back[0]))
        figures.update(daemon_from_s=lost[0], daemon_to_s=back[0], daemon_m=live, daemon_driven_m=live_truth,
                       daemon_err_pct=pct(live, live_truth), daemon_err_m=live - live_truth,
                       edges_pct=100.0 * edges / live_truth)
    for held, key in ((False, "replay"), (True, "replay_held")):
        replayed = replay_outage(work, a.cli, model, (out_start, out_len), a.gps_timeout, held)
        if replayed is None:
            print(f"{a.label}: {key}'s outage was not seen")
            continue
        dist, r_from, r_to = replayed
        r_truth = driven(truth, r_from, r_to)
        figures.update({f"{key}_from_s": r_from, f"{key}_to_s": r_to, f"{key}_m": dist,
                        f"{key}_driven_m": r_truth, f"{key}_err_pct": pct(dist, r_truth),
                        f"{key}_err_m": dist - r_truth})
    if "daemon_err_pct" in figures and "replay_err_pct" in figures:
        figures["daemon_minus_replay_pt"] = figures["daemon_err_pct"] - figures["replay_err_pct"]
    with open(os.path.join(work, "figures.json"), "w") as f:
        json.dump(figures, f, indent=1)
    for key in ("daemon_err_pct", "replay_err_pct", "daemon_minus_replay_pt", "edges_pct", "daemon_err_m",
                "replay_err_m", "replay_held_err_pct"):
        if key in figures:
            print(f"figure {a.label}_{key} = {figures[key]:+.2f}")
    if "daemon_m" in figures:
        print(f"  daemon {figures['daemon_m']:.1f} m over {figures['daemon_from_s']:.1f}-{figures['daemon_to_s']:.1f} s "
              f"(driven {figures['daemon_driven_m']:.1f} m), {late_hops or '?'} hops stepped late")
    for key in ("replay", "replay_held"):
        if f"{key}_m" in figures:
            print(f"  {key} {figures[f'{key}_m']:.1f} m over {figures[f'{key}_from_s']:.1f}-"
                  f"{figures[f'{key}_to_s']:.1f} s (driven {figures[f'{key}_driven_m']:.1f} m)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
