#!/usr/bin/env python3
"""Removal of a recorded path computed by mr-sim (PyPI `mr-sim`), for tests/mr_sim.rs.

Usage: mr-sim-check.py SAMPLES.csv SIZE_X SIZE_Y DX RADIUS KP BELT_SPEED
SAMPLES.csv: header `t,x,y,f` (s, m, m, N), the path in the part frame with the part's centre at (0, 0).
Prints JSON {"x": [...], "y": [...], "depth": [[...] per y]}: mr-sim's grid and profile (m).
Each interval between two samples is one step of mr-sim at the earlier sample's place and force, the
belt's speed plus the feed (the distance to the next sample over the time), as forcecell's
scenario::removal counts it. mr-sim's belt takes one speed: the sum is given to it.
"""
import csv
import json
import sys

import mr_sim


def main():
    path, sx, sy, dx, radius, kp, belt = sys.argv[1:8]
    sx, sy, dx, radius, kp, belt = map(float, (sx, sy, dx, radius, kp, belt))
    with open(path, newline="") as f:
        rows = [tuple(map(float, (r["t"], r["x"], r["y"], r["f"]))) for r in csv.DictReader(f)]
    Simulation = mr_sim.create_simulation(mr_sim.Flat, mr_sim.Round, mr_sim.Belt, mr_sim.Preston)
    sim = Simulation(sx, sy, dx=dx, dy=dx, dt=1.0, radius=radius, kp=kp)
    for (t0, x0, y0, f0), (t1, x1, y1, _) in zip(rows, rows[1:]):
        dt = t1 - t0
        if not dt > 0:
            continue
        if f0 <= 0:
            continue
        feed = ((x1 - x0) ** 2 + (y1 - y0) ** 2) ** 0.5 / dt
        sim.dt = dt
        sim.set_location(x0, y0)
        sim.set_force(f0)
        sim.set_speed(belt + feed)
        sim.step()
    json.dump(
        {
            "x": sim.X[0, :].tolist(),
            "y": sim.Y[:, 0].tolist(),
            "depth": sim.profile.tolist(),
        },
        sys.stdout,
    )


if __name__ == "__main__":
    main()
