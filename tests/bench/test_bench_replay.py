"""read_session: a log's settled steps, and its problems said where the log has them."""

from __future__ import annotations

from pathlib import Path

import pytest

from hydrojet_bench.bench.replay import read_session
from hydrojet_bench.errors import UserError
from hydrojet_bench.logs import LogWriter
from hydrojet_bench.logs.topics import Step
from hydrojet_bench.profile import PROFILES_DIR

SIM_METADATA = {"bench": {"profile_name": "sim", "profile_toml": (PROFILES_DIR / "sim.toml").read_text()}}
UPRIGHT = (1.0, 0.0, 0.0, 0.0)


def test_steps_out_of_order_name_the_message_not_a_dataset_row(tmp_path: Path) -> None:
    path = tmp_path / "reordered.mcap"
    with LogWriter(path, metadata=SIM_METADATA) as log:
        for index, time_s in enumerate((5.0, 10.0, 4.0)):
            log.write(Step(t_s=time_s + 0.01, index=index, count=3, sweep=-1, step=index,
                           jet_forces_n=(0.0, 0.0, 0.0), samples=40, tip_in_base_measured=UPRIGHT,
                           tip_position_in_base_m=None, time_s=time_s, base_orientation=UPRIGHT,
                           tip_orientation=UPRIGHT))
    with pytest.raises(UserError, match=r"reordered.mcap, message at t_s=4.01 s: /bench/step.time_s: time goes "
                                        r"backwards \(4.0 s after 10.0 s\)$"):
        read_session(path)
