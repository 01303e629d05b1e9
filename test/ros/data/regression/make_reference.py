"""Record the reference estimates of the pre-consolidation code on small generated bags.

Run with the code of commit 5a18045 on the path (it uses that version's API):
``git worktree add /tmp/ref 5a18045 && PYTHONPATH=/tmp/ref python make_reference.py test/ros/data/regression``.
"""

import json
import sys
from pathlib import Path

import numpy as np

from switchobs_core.design.lmi import design_table
from switchobs_core.model.schedule import Cycle
from switchobs_core.model.system import load_system
from switchobs_ros.bag.estimate import estimate, estimator_params
from switchobs_ros.bag.generate import GenerateConfig, generate

out = Path(sys.argv[1])
out.mkdir(parents=True, exist_ok=True)
sys_ = load_system("paper")
design_table(sys_, [Cycle.from_ts(2.0, 0.6)], delta=0.99, progress=False).save(out / "periodic.json")
design_table(sys_, [Cycle.from_ts(4.0, 0.5), Cycle.from_ts(3.0, 0.6), Cycle.from_ts(2.0, 0.4)], delta=0.99,
             progress=False).save(out / "sequence.json")
design_table(sys_, [], robust=(0.8, 1.2), delta=0.99, progress=False).save(out / "robust.json")
cases = {
    "periodic_mcap": (dict(schedule="periodic", rate=50.0, duration=6.0, noise_std=0.001, seed=1), "mcap",
                      {"gain_table": "periodic.json"}),
    "sequence_sqlite3": (dict(schedule="sequence:4,0.5;3,0.6;2,0.4", rate=50.0, duration=12.0, noise_std=0.01,
                              seed=2), "sqlite3",
                         {"gain_table": "sequence.json", "schedule.mode": "sequence",
                          "schedule.tau": [4.0, 3.0, 2.0], "schedule.s": [0.5, 0.6, 0.4]}),
    "random_mcap": (dict(schedule="random:0.8,1.2", rate=50.0, duration=6.0, noise_std=0.001, process_noise=0.01,
                         seed=3), "mcap",
                    {"gain_table": "robust.json", "schedule.mode": "robust", "schedule.h_min": 0.8,
                     "schedule.h_max": 1.2}),
}
meta = {}
for name, (g, storage, params) in cases.items():
    generate(out / name, GenerateConfig(**g), storage)
    p = dict(params, e0=5.0, gain_table=str(out / params["gain_table"]))
    res = estimate(out / name, estimator_params(overrides=p))
    np.savez(out / f"{name}.npz", stamps=res.stamps, x_hat=res.x_hat, envelope=res.envelope)
    meta[name] = {"generate": g, "storage": storage, "params": params}
    print(name, res.stamps.size, res.updates)
(out / "cases.json").write_text(json.dumps(meta, indent=1))
