"""The filter-error Table 2 study's bookkeeping (campaigns/studies/filter_error_table2.py): which
cells agree, the root mean square over seeds, the worst optimism per seed. Its flights and
calibrations are the study's (minutes), not a test's."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from campaigns.studies.filter_error_table2 import agreement, per_seed, summary


def _cells() -> pd.DataFrame:
    base = {"model_sensor_deg": 0.1, "truth_sensor_deg": 0.1, "cal_expected_deg": 0.2,
            "cal_realized_deg": 0.2, "said": "WARNING on_bound", "judged": True}
    return pd.DataFrame([
        # 30 % or 0.05 deg: 0.20 against 0.16 is within 0.05 deg; 0.40 against 0.30 is not (0.09 allowed)
        {"seed": 1, "cell": "a", "model_deg": 0.20, "truth_deg": 0.16, "verdict": "SUCCESS", **base},
        {"seed": 1, "cell": "b", "model_deg": 0.40, "truth_deg": 0.30, "verdict": "SUCCESS", **base},
        {"seed": 2, "cell": "a", "model_deg": 0.20, "truth_deg": 0.60, "verdict": "SUCCESS",
         **base, "judged": False},
        {"seed": 2, "cell": "b", "model_deg": 0.30, "truth_deg": 0.30, "verdict": "SUCCESS", **base},
        {"seed": 3, "cell": "(none)", "verdict": "FAILURE", "said": "FAILURE not_converged"},
    ])


def test_a_cell_agrees_within_30_percent_or_5_hundredths_of_a_degree():
    assert agreement(_cells().iloc[:4]).tolist() == [True, False, False, True]


def test_the_summary_is_the_root_mean_square_over_seeds():
    s = summary(_cells().iloc[:4])
    assert math.isclose(s.loc["a", "truth_deg"], math.sqrt((0.16 ** 2 + 0.60 ** 2) / 2))
    assert math.isclose(s.loc["a", "model/truth"], 0.20 / s.loc["a", "truth_deg"])
    assert s.loc["a", "cells_agreeing"] == "1 of 2" and s.loc["b", "cells_agreeing"] == "1 of 2"


def test_each_seed_names_its_worst_optimism_and_a_failed_one_has_no_table2():
    p = per_seed(_cells())
    assert p.loc[2, "worst_truth/model"].startswith("3.00 (a)")
    # the cell Table 2 does not judge is not its worst judged one
    assert p.loc[2, "worst_judged"] == "1.00 (b)" and p.loc[2, "not_judged"] == "a"
    assert p.loc[1, "cells_within"] == "1 of 2"
    assert p.loc[3, "cells_within"] == "no Table 2" and p.loc[3, "verdict"] == "FAILURE"
    assert np.all(p.index == [1, 2, 3])
