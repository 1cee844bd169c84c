"""Benchmark: our NREL SPA (lt_addon/sun/solar_position.py) against pvlib's over a year of hours.

For 13 places (every continent, both poles) and the 8,760 hourly UTC instants of ``--year``:
the worst |difference| in degrees against ``pvlib.solarposition.spa_python(how="numpy")`` (the
same algorithm; ``get_solarposition``'s method ``nrel_numpy``) of the refracted zenith, the
azimuth (where the Sun is 1-85 degrees high: near the zenith an azimuth is ill-conditioned),
and the angle between the two Sun directions; then the time of one year of hours at one place,
ours and pvlib's run alternately, best of ``--repeat`` in this run, with their ratio, and of
all the places at once (ours broadcasts the instants against the places; pvlib is called per
place).

Usage: python benchmarks/bench_solar_position.py [--year 2026] [--repeat 7] [--json FILE]
Needs pvlib (a test-only dependency in requirements.txt).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time

import numpy as np

PLACES = [
    ("London", 51.5074, -0.1278, 11.0),
    ("Reykjavik", 64.1466, -21.9426, 20.0),
    ("New York", 40.7128, -74.0060, 10.0),
    ("Golden CO (NREL)", 39.742476, -105.1786, 1830.14),
    ("Sao Paulo", -23.5505, -46.6333, 760.0),
    ("Nairobi", -1.2921, 36.8219, 1795.0),
    ("Cape Town", -33.9249, 18.4241, 10.0),
    ("Singapore", 1.3521, 103.8198, 15.0),
    ("Tokyo", 35.6762, 139.6503, 40.0),
    ("Sydney", -33.8688, 151.2093, 20.0),
    ("McMurdo", -77.846, 166.676, 10.0),
    ("North Pole", 90.0, 0.0, 0.0),
    ("South Pole", -90.0, 0.0, 2835.0),
]


def _best_of_both(fa, fb, repeat):
    """Best times of ``fa`` and ``fb``, run alternately (a busy machine slows both alike)."""
    best = [float("inf"), float("inf")]
    for _ in range(repeat):
        for k, fn in enumerate((fa, fb)):
            t0 = time.perf_counter()
            fn()
            best[k] = min(best[k], time.perf_counter() - t0)
    return best


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--year", type=int, default=2026)
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--json", default=None, help="also write the figures here")
    args = ap.parse_args(argv)

    try:
        import pandas as pd
        from pvlib import __version__ as pvlib_version
        from pvlib import solarposition as pvs
    except ImportError:
        sys.exit("bench_solar_position: needs pvlib (pip install -r requirements.txt)")
    from relightable_textures.lt_addon.sun.solar_position import (DELTA_T_2020S, solar_position,
                                                                   sun_direction)

    t = np.arange(np.datetime64(f"{args.year}-01-01T00:00"),
                  np.datetime64(f"{args.year + 1}-01-01T00:00"), np.timedelta64(1, "h"))
    idx = pd.DatetimeIndex(t, tz="UTC")
    air = dict(pressure_hpa=1013.25, temperature_c=12.0, delta_t=DELTA_T_2020S)

    def ours(lat, lon, h):
        return solar_position(t, lat, lon, h, **air)

    def theirs(lat, lon, h):
        return pvs.spa_python(idx, lat, lon, altitude=h, pressure=air["pressure_hpa"] * 100.0,
                              temperature=air["temperature_c"], delta_t=air["delta_t"],
                              how="numpy")

    print(f"NREL SPA vs pvlib {pvlib_version} spa_python(how='numpy'), {len(t)} hourly "
          f"instants of {args.year}, delta_t {air['delta_t']} s; worst |difference| in degrees")
    print(f"{'place':18s} {'lat':>9s} {'lon':>10s} {'zenith':>9s} {'azimuth':>9s} "
          f"{'direction':>9s}  hours up")
    rows = []
    for name, lat, lon, h in PLACES:
        a, p = ours(lat, lon, h), theirs(lat, lon, h)
        dz = np.abs(a.zenith - p["apparent_zenith"].to_numpy())
        daz = np.abs((a.azimuth - p["azimuth"].to_numpy() + 180.0) % 360.0 - 180.0)
        mid = (a.elevation > 1.0) & (a.elevation < 85.0)
        d1 = sun_direction(a.elevation, a.azimuth)
        d2 = sun_direction(p["apparent_elevation"].to_numpy(), p["azimuth"].to_numpy())
        ang = np.degrees(2.0 * np.arcsin(np.clip(np.linalg.norm(d1 - d2, axis=1) / 2, 0, 1)))
        row = {"place": name, "latitude": lat, "longitude": lon, "elevation_m": h,
               "zenith": float(dz.max()), "azimuth": float(daz[mid].max()) if mid.any() else None,
               "direction": float(ang.max()), "hours_up": int((a.elevation > 0).sum())}
        rows.append(row)
        az = f"{row['azimuth']:9.2e}" if row["azimuth"] is not None else f"{'-':>9s}"
        print(f"{name:18s} {lat:9.4f} {lon:10.4f} {row['zenith']:9.2e} {az} "
              f"{row['direction']:9.2e}  {row['hours_up']}")
    worst = {k: max(r[k] for r in rows if r[k] is not None)
             for k in ("zenith", "azimuth", "direction")}
    print(f"{'worst':18s} {'':9s} {'':10s} {worst['zenith']:9.2e} {worst['azimuth']:9.2e} "
          f"{worst['direction']:9.2e}")

    name, lat, lon, h = PLACES[0]
    ours(lat, lon, h), theirs(lat, lon, h)                        # warm both
    t_ours, t_pv = _best_of_both(lambda: ours(lat, lon, h), lambda: theirs(lat, lon, h),
                                 args.repeat)
    lats = np.array([p[1] for p in PLACES])
    lons = np.array([p[2] for p in PLACES])
    hs = np.array([p[3] for p in PLACES])
    t_ours_all, t_pv_all = _best_of_both(
        lambda: solar_position(t[:, None], lats, lons, hs, **air),
        lambda: [theirs(*p[1:]) for p in PLACES], max(1, args.repeat // 3))
    print(f"\ntime of {len(t)} instants at {name} (best of {args.repeat}, this run, "
          f"{os.cpu_count()} CPUs): ours {t_ours * 1e3:.1f} ms, pvlib {t_pv * 1e3:.1f} ms, "
          f"ours/pvlib {t_ours / t_pv:.2f}")
    print(f"all {len(PLACES)} places: ours (one call, instants x places) "
          f"{t_ours_all * 1e3:.1f} ms, pvlib (one call per place) {t_pv_all * 1e3:.1f} ms, "
          f"ours/pvlib {t_ours_all / t_pv_all:.2f}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"year": args.year, "instants": int(len(t)), "pvlib": pvlib_version,
                       "numpy": np.__version__, "python": platform.python_version(),
                       "places": rows, "worst_deg": worst,
                       "seconds": {"ours_one_place": t_ours, "pvlib_one_place": t_pv,
                                   "ours_all_places": t_ours_all,
                                   "pvlib_all_places": t_pv_all},
                       "ratio_one_place": t_ours / t_pv,
                       "ratio_all_places": t_ours_all / t_pv_all}, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
