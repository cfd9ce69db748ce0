"""Which drawbar run would tell apart two models that explain a campaign about as well.

Where `juno diagnose` reports a candidate as explaining the data about as well as the cause
(``equally_good``), the campaign's runs cannot tell the two apart.  A further run can, if the two
fitted models predict it differently.  This module predicts the simplest such run, a steady
drawbar test on flat ground (synthesize.steady_slip: a constant throttle, the load ramped in over
4 s, the mean slip of the last 6 s), under each model over a ladder of loads and two throttles,
and gives the load and throttle where the predicted slips differ most.

Why a drawbar test at a heavier load: a grouser's lugs (shear at R + h) need more torque per unit
of thrust, as if h / (R + h) of the torque were lost in the drivetrain, so at the campaign's
moderate slips the two models fit alike; the grouser's thrust gain raises the traction limit, which
only a run near that limit shows (docs/diagnosis.md, "Known limits").
The difference is in the models' predictions, not a test: whether it is measurable depends on how
steady the run can be held.
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from .campaign import Campaign
from .identify import steady_averages
from .simulator import JunoFMU
from .synthesize import HEAVY_THROTTLE, THROTTLE, steady_slip

#: Drawbar loads (N) of the ladder: from below the synthetic campaigns' lightest run (320 N) to
#: beyond the load at which a grouser truth settles at 70 % slip at HEAVY_THROTTLE (950-1160 N,
#: synthesize.load_for_slip); at HEAVY_THROTTLE the fits measured stall by 1400-1600 N.
LOADS = tuple(float(f) for f in np.arange(200.0, 1601.0, 100.0))
#: Throttles (0-1): the campaigns' drawbar runs' and the heavy run's (synthesize).
THROTTLES = (THROTTLE, HEAVY_THROTTLE)


def slip_ladder(fmu: JunoFMU, params: Mapping[str, object], loads: tuple[float, ...] = LOADS,
                throttle: float = THROTTLE) -> np.ndarray:
    """Steady slip (-; 1 where the rover stalls) of the model ``params`` at each drawbar load (N)
    of ``loads``, at ``throttle``."""
    return np.array([steady_slip(fmu, dict(params), load, throttle) for load in loads])


def heaviest_drawbar_load(campaign: Campaign) -> float:
    """The heaviest load (N) of the campaign's drawbar runs: the largest measured drawbar force
    averaged over a run's steady window (identify.steady_averages; the whole run if it has
    none); 0 without drawbar runs."""
    return max((steady_averages(campaign, run).drawbar for run in campaign.runs if run.kind == "drawbar"),
               default=0.0)


def telling_apart(fmu: JunoFMU, named: tuple[str, Mapping[str, object]],
                  tied: Mapping[str, Mapping[str, object]], campaign_load: float = 0.0,
                  loads: tuple[float, ...] = LOADS, throttles: tuple[float, ...] = THROTTLES
                  ) -> list[dict[str, Any]]:
    """For each model in ``tied`` (name -> FMU parameters), the steady drawbar run at which its
    predicted slip differs most from the named model's (``named`` = (name, FMU parameters)).

    Returns one dict per tied model: ``models`` (the named one first), ``throttle``, ``load_N``,
    ``slip`` (name -> predicted steady slip there), ``difference`` (the absolute slip
    difference there), ``difference_within_campaign`` (the largest at that throttle at loads up
    to ``campaign_load`` N, the campaign's heaviest; 0 if none is that light) and ``ladder``
    (the loads, and each model's slips at every load at that throttle), so a reader sees where
    the two part."""
    name, params = named
    own = {t: slip_ladder(fmu, params, loads, t) for t in throttles}
    within = np.asarray(loads) <= campaign_load
    out = []
    for other, other_params in tied.items():
        best: dict[str, Any] | None = None
        for t in throttles:
            theirs = slip_ladder(fmu, other_params, loads, t)
            diff = np.abs(own[t] - theirs)
            k = int(np.argmax(diff))
            if best is None or diff[k] > best["difference"]:
                best = {"models": [name, other], "throttle": float(t), "load_N": float(loads[k]),
                        "slip": {name: float(own[t][k]), other: float(theirs[k])},
                        "difference": float(diff[k]),
                        "difference_within_campaign": float(np.max(diff[within])) if np.any(within) else 0.0,
                        "ladder": {"load_N": [float(x) for x in loads], name: own[t].tolist(),
                                   other: theirs.tolist()}}
        out.append(best)
    return out
