# %% [markdown]
# # Find the missing physics, from Python
#
# The README's tutorial ("Tutorial: find the missing physics") with the Python API in
# place of the commands. Record the session first (about 50 s on the simulated rig):
#
#     .venv/bin/hydrojet-bench run --profile sim-mystery --log sessions/mystery.mcap
#
# then run this file as a script (`python docs/examples/notebook_tutorial.py [DATA]
# [PROFILE] [FIGURES_DIR]`) or open it as a notebook (the `# %%` cells: VS Code,
# Jupyter with jupytext). DATA defaults to that log; a CSV file needs its PROFILE.

# %%
import sys
from pathlib import Path

import hydrojet_bench as hj

data_path = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("sessions/mystery.mcap")
profile = sys.argv[2] if len(sys.argv) > 2 else None  # a session log brings its own
figures = Path(sys.argv[3]) if len(sys.argv) > 3 else Path("sessions/notebook-figures")
figures.mkdir(parents=True, exist_ok=True)

data = hj.load(data_path, profile)
steps = data.to_pandas()  # one row per settled step: time_s, sweep, step, q1_n..q3_n, measured pose
print(f"{len(steps)} steps, {int((steps.sweep == -1).sum())} of them calibration poses")

# %% [markdown]
# ## Which effect is missing?
# `diagnose` calibrates the nominal model and the model plus each candidate effect on part
# of the session and scores them on the held-out repetitions, against the noise floor
# measured from the data itself.

# %%
found = hj.diagnose(data)
print(f"verdict: {found.verdict}")
print(found.to_pandas()[["effect", "heldout_orientation_rmse_deg", "explained_fraction", "qualifies"]])
found.plot().savefig(figures / "diagnose.png")

# %% [markdown]
# ## Calibrate without and with it, and watch the error fall
# A calibration is used directly as the parameters of `compare` (or saved with
# `.save("after.toml")` for the commands).

# %%
before = hj.calibrate(data)
added = [] if found.verdict in ("none", "unexplained") else [found.verdict]
after = hj.calibrate(data, effects=added)
print(after.parameters_table())

result = hj.compare(data, after, baseline=before, online=True)
table = result.table_ii()
print(table[table.group == "all"])
errors = result.to_pandas()  # one row per step and method: commanded q, measured and predicted poses, errors
print(errors.groupby(["method", "sweep"])["orientation_error_deg"].agg(["mean", "max"]))
result.plot().savefig(figures / "compare.png")

old = result.baseline["ref"].overall.orientation_rmse_deg
new = result.results["ref"].overall.orientation_rmse_deg
print(f"Ref. orientation RMSE {old:.2f} deg without {', '.join(added) or 'an added effect'}, {new:.2f} deg with it")
