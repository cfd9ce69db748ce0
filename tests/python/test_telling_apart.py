"""What would tell apart two models that a campaign cannot (juno.telling_apart).

Where the diagnosis reports a candidate as equally good as the cause, it also predicts the
steady drawbar run on flat ground at which the two fitted models differ most.  These tests pin
that prediction on cases whose answer is known from the physics: a model against itself, a
registration (which flat ground cannot see), and the grouser and drivetrain loss fitted to one
synthetic campaign, whose lugs mimic the loss at moderate slip but whose thrust gain raises the
traction limit.
"""

from __future__ import annotations

from juno.telling_apart import LOADS, heaviest_drawbar_load, telling_apart

pytest_plugins = ["harness_fixtures"]

#: Two fits the diagnosis reported tied on a grouser campaign (strength 0.736; truth: thrust
#: gain 0.258, lugs 18.4 mm), rounded.  It named the loss, the grouser equally good.
LOSS_FIT = {"soil.kh": 123858.0, "soil.eta": 0.48492, "soil.gamma": 0.078452, "soil.Kvx": 0.58638,
            "drive.lossFraction": 0.062149}
GROUSER_FIT = {"soil.kh": 153607.0, "soil.eta": 0.53942, "soil.gamma": 0.072715, "soil.Kvx": 0.87641,
               "grouser.thrustGain": 0.27333, "grouser.lugHeight": 0.017314}
#: That campaign's truth (truth.json).
TRUTH = {"soil.kh": 151062.0, "soil.eta": 0.53419, "soil.gamma": 0.07644, "soil.Kvx": 0.87078,
         "grouser.thrustGain": 0.2576, "grouser.lugHeight": 0.0184}
#: The heaviest of that campaign's three drawbar runs is about 720 N (synthesize.HELD_LOADS).
CAMPAIGN_LOAD = 720.0


def test_a_model_is_not_told_apart_from_itself(harness_fmu):
    (a,) = telling_apart(harness_fmu, ("drivetrain_loss", LOSS_FIT), {"copy": dict(LOSS_FIT)}, CAMPAIGN_LOAD)
    assert a["difference"] == 0.0 and a["difference_within_campaign"] == 0.0
    assert a["models"] == ["drivetrain_loss", "copy"]


def test_no_drawbar_run_on_flat_ground_tells_a_registration_from_the_scan_as_it_is(harness_fmu):
    registered = {**LOSS_FIT, "terrain.offsetX": 0.3, "terrain.offsetY": -0.2, "terrain.offsetZ": 0.05,
                  "terrain.offsetYaw": 0.04}
    (a,) = telling_apart(harness_fmu, ("base", LOSS_FIT), {"terrain_offset": registered}, CAMPAIGN_LOAD)
    # On flat ground the offsets move the plane along itself and raise it by offsetZ: the rover
    # runs offsetZ higher, so the slips agree to rounding (measured: 8e-15), not bit for bit.
    assert a["difference"] < 1e-9


def test_the_grouser_and_the_loss_it_mimics_part_only_beyond_the_campaigns_loads(harness_fmu):
    """Up to the campaign's loads the two fits settle within about 0.01 of slip of each other
    (why the campaign could not tell them apart); near the traction limit the loss's rover
    slips far more, since the loss lowers the torque but not the limit the lugs raise."""
    (a,) = telling_apart(harness_fmu, ("drivetrain_loss", LOSS_FIT), {"grouser": GROUSER_FIT}, CAMPAIGN_LOAD)
    assert a["difference_within_campaign"] < 0.02
    assert a["difference"] > 0.05
    assert a["load_N"] > CAMPAIGN_LOAD
    assert a["slip"]["drivetrain_loss"] > a["slip"]["grouser"]
    ladder = a["ladder"]
    assert ladder["load_N"] == list(LOADS)
    k = ladder["load_N"].index(a["load_N"])
    assert ladder["grouser"][k] == a["slip"]["grouser"]


def test_the_campaigns_heaviest_load_is_its_heaviest_drawbar_runs_steady_force(clean_campaign):
    """The synthetic campaign pulls 320, 520 and 720 N (each +-40 N, in a random order;
    synthesize.HELD_LOADS): the heaviest is the 720 N run's, not the lighter ones'."""
    assert 720.0 - 80.0 < heaviest_drawbar_load(clean_campaign.campaign) < 720.0 + 80.0


def test_the_run_that_parts_the_two_fits_shows_which_one_the_truth_is(harness_fmu):
    """Run on the truth, the proposed run settles where the right model (the grouser) predicts,
    not where the loss the campaign named does.  Measured on seven campaigns (five grouser, two
    drivetrain_loss): the truth within 0.024 of slip of the right model, 0.08-0.29 from the
    other."""
    from juno.synthesize import steady_slip
    (a,) = telling_apart(harness_fmu, ("drivetrain_loss", LOSS_FIT), {"grouser": GROUSER_FIT}, CAMPAIGN_LOAD)
    truth = steady_slip(harness_fmu, TRUTH, a["load_N"], a["throttle"])
    assert abs(truth - a["slip"]["grouser"]) < 0.25 * abs(truth - a["slip"]["drivetrain_loss"])
