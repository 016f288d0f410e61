"""Tables of the pendulum runs (runs/) : learning summary per variant and mechanism per residual variant."""

import glob
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from sb3_er.experiments.metrics import rise_time

pd.set_option("display.width", 250)
pd.set_option("display.max_columns", 60)
OUT = Path(sys.argv[1] if len(sys.argv) > 1 else "runs")
ORDER = [
    "er",
    "er_sigma",
    "res_taken_z1",
    "res_taken_z0.5",
    "res_next_z1",
    "res_next_z0.5",
    "ressig_taken_z1",
    "ressig_taken_z0.5",
    "ressig_next_z1",
    "ressig_next_z0.5",
]
rows = []
for v in ORDER:
    files = sorted(glob.glob(str(OUT / v / "seed_?.csv")))
    if not files:
        continue
    curves, div, div_ep, seeds = [], [], [], []
    for f in files:
        d = pd.read_csv(f)
        seeds.append(int(Path(f).stem.split("_")[1]))
        if d["diverged"].any():
            div.append(seeds[-1])
            div_ep.append(int(d["episode"].max()) + 1)
        else:
            curves.append(d["return"].to_numpy())
    if curves:
        c = np.vstack(curves)
        m = c.mean(0)
        ep = np.arange(1, m.size + 1)
        best = m.max()
        rise = rise_time(ep, m)
        per_seed_last10 = c[:, -10:].mean(1)
        rows.append(
            {
                "variant": v,
                "runs": len(files),
                "diverged": len(div),
                "diverged at episode (seed)": ", ".join(f"{e} (s{s})" for e, s in zip(div_ep, div, strict=True)) or "-",
                "rise [ep]": rise,
                "best mean": round(best),
                "last10 mean": round(m[-10:].mean()),
                "last10 per seed": " ".join(f"{x / 1000:.1f}k" for x in per_seed_last10),
                "first mean": round(m[0]),
                "goal rate last10": None,
            }
        )
    else:
        rows.append(
            {
                "variant": v,
                "runs": len(files),
                "diverged": len(div),
                "diverged at episode (seed)": ", ".join(f"{e} (s{s})" for e, s in zip(div_ep, div, strict=True)),
            }
        )
print(pd.DataFrame(rows).drop(columns=["goal rate last10"]).to_string(index=False))

# mechanism, mean over seeds per phase (finite runs only at that phase)
keys = [
    "updates",
    "mean_abs_delta",
    "frac_delta_neg",
    "share_ak",
    "share_aeps",
    "share_astored",
    "share_ak_when_same_eps",
    "p_aeps_eq_ak",
    "p_astored_eq_ak",
    "p_aeps_eq_astored",
    "dQ(s',a_k)/ad plain",
    "dQ(s',a_k)/ad rule",
    "dQ(s',a_eps)/ad plain",
    "dQ(s',a_eps)/ad rule",
    "dQ(s,a_k)/ad rule",
    "frac_resterm_raises_Q(s',a_res)",
    "frac_resterm_raises_non_taken_next",
    "frac_net_raise_Q(s',a_res)",
    "frac_net_raise_non_taken_next",
    "frac_a_res_ne_greedy_before",
    "frac_greedy_flips_to_a_res",
]
for v in ["er", "res_taken_z1", "res_taken_z0.5", "res_next_z1", "res_next_z0.5"]:
    fs = sorted(glob.glob(str(OUT / v / "seed_?_mechanism.csv")))
    if not fs:
        continue
    d = pd.concat([pd.read_csv(f).assign(seed=i) for i, f in enumerate(fs)])
    d = d[d["mean_abs_delta"] < 1e6]
    k = [x for x in keys if x in d.columns]
    t = d.groupby("phase")[k].mean().T
    t["pooled"] = d[k].mean()
    t.loc["n_seeds"] = d.groupby("phase").size().tolist() + [len(d)]
    print(f"\n== {v} ({len(fs)} seeds) ==")
    print(t.round(3).to_string())
