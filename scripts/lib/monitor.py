#!/usr/bin/python3
"""Watches a running gearpulsed through `gearpulsectl status --json` while a simulated drive plays.

Prints one compact line every few seconds (and at once whenever the speed source changes), then, when
the drive is over, the pulse count against the drive's true distance and how long the daemon took to
switch to engine-derived speed after the last GPS fix. Writes the figures to WORK/summary.json.
"""
import argparse
import bisect
import csv
import json
import os
import subprocess
import sys
import time


def load_truth(path):
    ts, speeds, dist = [], [], [0.0]
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            ts.append(float(row["t"]))
            speeds.append(float(row["speed"]))
    for i in range(1, len(ts)):
        dist.append(dist[-1] + 0.5 * (speeds[i] + speeds[i - 1]) * (ts[i] - ts[i - 1]))
    return ts, speeds, dist


def at(ts, values, t):
    i = max(0, min(len(ts) - 1, bisect.bisect_right(ts, t) - 1))
    return values[i]


def alive(pid):
    try:
        os.kill(pid, 0)
        return True
    except OSError:
        return False


def status(ctl, sock):
    try:
        out = subprocess.run([ctl, "--socket", sock, "status", "--json"], capture_output=True, text=True,
                             timeout=2).stdout
        return json.loads(out)
    except (subprocess.TimeoutExpired, json.JSONDecodeError):
        return None


def fmt(v, spec, missing="-"):
    return missing if v is None else format(v, spec)


def model_text(s):
    """The model as status shows it: the known gears' thetas, and the learning schedule while young."""
    m = s.get("model", {})
    gears = m.get("known_gears", [])
    learning = m.get("learning", {})
    text = "model: " + (" ".join(f"{g.get('theta', 0):.4f}" for g in gears) if gears else "none")
    if learning.get("young"):
        text += f"  learning: {learning.get('moving_time', 0):.0f} s moving"
        if not gears:
            text += f", steady pairs in one gear {learning.get('cluster_pairs')}/{learning.get('first_fit_pairs')}"
        elif learning.get("next_refit") is not None:
            text += f", next refit at {learning['next_refit']:.0f} s"
    elif gears:
        text += "  (settled)"
    return text


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--work", required=True)
    ap.add_argument("--ctl", required=True)
    ap.add_argument("--ppk", type=float, required=True)
    ap.add_argument("--outage", default="")
    ap.add_argument("--print-every", type=float, default=3.0)
    ap.add_argument("--poll", type=float, default=0.25)
    ap.add_argument("--until-pid", type=int, required=True, help="the feeder: the drive ends when it exits")
    ap.add_argument("--quiet", action="store_true")
    ap.add_argument("--model", action="store_true",
                    help="add the model's known gears and learning schedule to each line, and print a line "
                         "at once whenever the model changes")
    a = ap.parse_args()

    work = a.work
    sock = os.path.join(work, "control.sock")
    ts, speeds, dist = load_truth(os.path.join(work, "drive", "truth.csv"))
    t0 = float(open(os.path.join(work, "drive.t0")).read())  # the drive's t = 0 (harness.sh)
    out_start, out_len = (float(x) for x in a.outage.split(":")) if a.outage else (None, 0.0)

    last_print = -1e9
    last_source = None
    last_model = None
    seen_gps = False
    # First status whose speed comes from the engine after GPS was used (source engine, or coast: the clutch
    # out, the speed carried by the synthesis' declutched model): (elapsed, gps age).
    first_engine = None
    outage_polls = {}
    samples = []
    while alive(a.until_pid):
        now = time.time()
        el = now - t0
        s = status(a.ctl, sock)
        if s is None:
            time.sleep(a.poll)
            continue
        source = s.get("source")
        gps = s.get("gps", {})
        trk = s.get("tracker", {})
        speed = s.get("speed") or 0.0
        samples.append((el, source, speed, at(ts, speeds, el)))
        if out_start is not None and out_start + 5 <= el <= out_start + out_len - 2:
            outage_polls[source] = outage_polls.get(source, 0) + 1
        seen_gps = seen_gps or source == "gps"
        if source in ("engine", "coast") and seen_gps and first_engine is None:
            first_engine = (el, gps.get("age"))
        model = model_text(s) if a.model else ""
        if not a.quiet and (el - last_print >= a.print_every or source != last_source or model != last_model):
            last_print = el
            if a.model:
                print(f"  t={el:5.0f}s  source={source:<6} gear={s.get('gear', 0)}  "
                      f"speed={speed * 3.6:5.1f} km/h (true {at(ts, speeds, el) * 3.6:5.1f})  {model}", flush=True)
            else:
                print(f"  t={el:5.0f}s  source={source:<6} gear={s.get('gear', 0)}  "
                      f"speed={speed * 3.6:5.1f} km/h (true {at(ts, speeds, el) * 3.6:5.1f})  "
                      f"gps={gps.get('state', '?'):<12} track={fmt(trk.get('freq'), '5.1f')} Hz "
                      f"{fmt(trk.get('snr_db'), '4.1f')} dB  pulses={s.get('pulses', 0)}", flush=True)
        last_model = model
        last_source = source
        time.sleep(max(0.0, a.poll - (time.time() - now)))

    time.sleep(1.0)  # the last pulses of the stop are already out; let the reader drain the PTY
    final = status(a.ctl, sock) or {}
    counted = os.path.getsize(os.path.join(work, "pulses.bin"))
    distance = dist[-1]
    expected = distance / 1000.0 * a.ppk
    error = 100.0 * (counted - expected) / expected if expected > 0 else float("nan")
    summary = {
        "distance_m": distance,
        "pulses_expected": expected,
        "pulses_counted": counted,
        "pulses_reported": final.get("pulses"),
        "pulse_error_percent": error,
        "engine_after_last_fix_s": first_engine[1] if first_engine else None,
        "engine_first_at_s": first_engine[0] if first_engine else None,
        "outage_sources": outage_polls,
    }
    with open(os.path.join(work, "summary.json"), "w") as f:
        json.dump(summary, f, indent=1)
    print(f"drive over: {distance / 1000:.3f} km -> {expected:.0f} pulses expected at {a.ppk:g}/km; "
          f"counted on the PTY {counted} ({error:+.2f} %), daemon reports {final.get('pulses')}")
    if first_engine and first_engine[1] is not None:
        print(f"GPS loss -> engine-derived speed: {first_engine[1]:.2f} s after the last fix "
              f"(at t={first_engine[0]:.0f}s of the drive)")
    else:
        print("engine-derived speed never seen")
    if outage_polls:
        total = sum(outage_polls.values())
        print("inside the outage the source was: " +
              ", ".join(f"{k} {100.0 * v / total:.0f} %" for k, v in sorted(outage_polls.items())))
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except KeyboardInterrupt:
        sys.exit(130)
