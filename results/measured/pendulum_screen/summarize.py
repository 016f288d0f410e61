import sys
from pathlib import Path
import numpy as np, pandas as pd
from sb3_er.experiments.metrics import rise_time
root = Path(sys.argv[1] if len(sys.argv) > 1 else "/work/scratch/pendulum/runs")
rows = []
for cdir in sorted(root.iterdir()):
    for adir in sorted(cdir.iterdir()):
        frames = [pd.read_csv(f) for f in sorted(adir.glob("seed_*.csv"))]
        if not frames: continue
        n = min(len(f) for f in frames)
        curves = np.array([f["return"].values[:n] for f in frames])
        mean = curves.mean(0)
        ep = np.arange(1, n + 1)
        goal = np.mean([f["goal_reached"].values[:n].mean() for f in frames])
        rows.append(dict(candidate=cdir.name, algo=adir.name, seeds=len(frames), episodes=n,
                         rise=rise_time(ep, mean), best=mean.max(), r1=mean[0],
                         r10=mean[9] if n >= 10 else np.nan, r20=mean[19] if n >= 20 else np.nan,
                         r50=mean[49] if n >= 50 else np.nan,
                         last10=mean[-10:].mean(), goal_frac=goal,
                         cpu_s=np.mean([f["cpu_s"].iloc[0] for f in frames]),
                         wall_s=np.mean([f["wall_s"].iloc[0] for f in frames])))
t = pd.DataFrame(rows)
pd.set_option("display.width", 200)
print(t.to_string(index=False, float_format=lambda x: f"{x:.0f}" if abs(x) >= 10 else f"{x:.2f}"))
t.to_csv(root.parent / f"summary_{root.name}.csv", index=False)
# ER/ER-sigma best against Sarsa(lambda)'s best, in % of |Sarsa| (the thesis's "difference" column uses end performance)
piv = t.pivot(index="candidate", columns="algo", values="best")
for algo in ("er", "er_sigma"):
    if algo in piv:
        piv[f"{algo}_vs_sarsa_%"] = 100 * (piv[algo] - piv["sarsa_lambda"]) / piv["sarsa_lambda"].abs()
print(piv.round(0).to_string())
