"""The joint fit on two cores (juno.identify.identify_joint with workers=2) is the serial fit.

In parallel, each residual evaluation simulates the drawbar runs as parallel tasks and the four
points of each finite-difference Jacobian are evaluated as parallel tasks, in worker processes
that hold their own FMU instance.  The optimiser sees the same numbers in the same order, so
the optimum, its uncertainty and the number of model evaluations are identical bit for bit.
Wall times are printed (``-s``), not asserted: the machine is shared (``juno bench`` measures).
"""

from __future__ import annotations

import time

import numpy as np

from harness_fixtures import say
from juno.identify import identify_joint
from juno.simulator import SOIL_PARAMETERS

pytest_plugins = ["harness_fixtures"]


def test_the_two_core_joint_fit_is_the_serial_fit(harness_fmu, noisy_campaign, noisy_joint):
    """The serial fit is the session's noisy_joint (identify_joint with workers=1)."""
    c = noisy_campaign.campaign
    serial, t_serial = noisy_joint, noisy_joint.wall_time
    t = time.perf_counter()
    two = identify_joint(harness_fmu, c, workers=2)
    t_two = time.perf_counter() - t
    say(f"joint fit on the noisy campaign: serial {t_serial:.1f} s, 2 workers {t_two:.1f} s, "
        f"{serial.evaluations} model evaluations each")
    for k in SOIL_PARAMETERS:
        assert two.params[k] == serial.params[k], (k, two.params[k], serial.params[k])
        assert two.std[k] == serial.std[k], (k, two.std[k], serial.std[k])
    assert two.cost == serial.cost
    assert two.evaluations == serial.evaluations
    assert two.singular_values == serial.singular_values
    assert np.array_equal(two.correlation, serial.correlation)
    assert two.runs == serial.runs
    # The fit itself is sound (a broken fit returned twice would pass the comparisons above).
    truth = noisy_campaign.soil
    assert all(abs(serial.params[k] - truth[k]) <= 3 * serial.std[k] for k in SOIL_PARAMETERS)
