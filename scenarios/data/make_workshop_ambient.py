"""Regenerate ``workshop_ambient_72h.csv``: a synthetic (not measured) 72 h workshop record.

Friday 18:00 to Monday 18:00, one reading every 10 min: a weekend day/night
cycle (18.5 °C ± 1.8 K, warmest at 16:00, heating on set-back), the heating
back to working level from Monday 06:00 (+2 K, 1.5 h time constant), a loading
door open for 20 min at Monday 10:00 (−4 K, 1 h recovery), a slow random
wander of the weather and 0.03 K reading noise, rounded to 0.01 °C.
Run from this folder: ``python make_workshop_ambient.py``.
"""
import numpy as np

rng = np.random.default_rng(2024)
t = np.arange(0, 72 * 3600 + 1, 600.0)
clock = 18.0 + t / 3600.0                      # hours since Friday 00:00
day = np.floor(clock / 24.0)                   # 0 Fri, 1 Sat, 2 Sun, 3 Mon
hour = clock % 24.0
base = 18.5 + 1.8 * np.cos(2 * np.pi * (hour - 16.0) / 24.0)
monday = (day == 3) & (hour >= 6.0)
base += np.where(monday, 2.0 * (1 - np.exp(-(hour - 6.0) / 1.5)), 0.0)
door = (day == 3) & (hour >= 10.0)
s = (hour - 10.0) * 3600.0
base -= np.where(door, np.where(s <= 1200, 4.0 * s / 1200, 4.0 * np.exp(-(s - 1200) / 3600.0)), 0.0)
walk = np.cumsum(rng.normal(0, 0.03, t.size))
walk -= np.linspace(walk[0], walk[-1], t.size)
value = np.round(base + walk + rng.normal(0, 0.03, t.size), 2)
with open("workshop_ambient_72h.csv", "w") as f:
    f.write("time_s,ambient_degC\n")
    for a, b in zip(t, value):
        f.write(f"{a:.0f},{b:.2f}\n")
