"""Screen on Sarsa(lambda) what thesis 4.2.3 prints and the default does not follow: the feet kept parallel to the
floor.

Run from the repository root (10 seeds, 12000 s of learning time, one `sb3-er reproduce` folder per candidate; resumes):

    nice -n 10 .venv/bin/python benchmarks/leo_sarsa_screen.py [--only NAME ...] [--summary-only] [--out DIR]

Thesis 4.2.3: "the ankle actuators are controlled so that the feet remain parallel with the ground"; Erik Schuitema's
code (the default) holds each ankle joint at 3.72 degrees to its shank instead. The default's own row is its committed
20-seed reproduction (results/measured/leo, seeds 0-9 here). A LEO run takes about 5 minutes of one core, so the
open rate filter (``filter_rates=False``) and the start variation (``start_noise``) were not screened.
"""

from pathlib import Path

from sb3_er.experiments.screen import Candidate, screen_command

#: The screen's folder (--out): a sub-folder per candidate, its summary.md and summary.csv.
OUT = Path(__file__).resolve().parents[1] / "results" / "measured" / "leo_sarsa_screen"
CANDIDATES = [
    Candidate(
        "default",
        {},
        "Erik's ankles (3.72 deg to the shank), filtered rates, start noise 0.05 rad",
        folder=OUT.parent / "leo",
    ),
    Candidate(
        "floor_parallel_ankles",
        {"floor_parallel_ankles": True},
        "printed: feet held parallel to the floor (Erik's autoActuateAnkles)",
        printed=frozenset({"the feet remain parallel with the ground"}),
    ),
]

if __name__ == "__main__":
    screen_command(
        "leo",
        CANDIDATES,
        OUT,
        "LEO: Sarsa(λ) screen (thesis Table 6.3)",
        notes=" ".join(__doc__.split("\n\n", 1)[0].split())
        + " 12000 s of learning time per run; every 200 s, one greedy 25 s run. The printed feet's 10 runs were made "
        "by one code version, the one of Table 6.3's reruns.",
    )
