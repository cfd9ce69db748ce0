"""The catalogue of model extensions the diagnosis can propose (CANDIDATES), each with the physical
cause it stands for, its parameters, where its search starts and when it counts as switched on."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Separates a parameter's FMU name from the runs it applies to: ``NAME@RUN,RUN`` is given to
#: those runs as NAME and to no other run (problem.residuals_or_failure).  Run ids cannot hold
#: either character (juno.campaign's manifest check).
RUNS_MARK, RUNS_SEPARATOR = "@", ","


def for_runs(name: str, runs: tuple[str, ...] | list[str]) -> str:
    """The name of FMU parameter ``name`` applied to ``runs`` only (RUNS_MARK)."""
    return name + RUNS_MARK + RUNS_SEPARATOR.join(runs)


def unqualified(name: str) -> str:
    """The FMU name of a parameter (``name`` without the runs it is applied to, for_runs)."""
    return name.split(RUNS_MARK, 1)[0]


def run_parameters(params: dict[str, object], run_id: str) -> dict[str, object]:
    """The FMU parameters run ``run_id`` is replayed with: the unqualified ones, overridden by
    those applied to that run (for_runs); parameters applied to other runs only are left out.
    A tied extension parameter is given as the FMU variables it sets (fmu_parameters)."""
    out: dict[str, object] = {}
    own: dict[str, object] = {}
    for k, v in params.items():
        if RUNS_MARK not in k:
            out[k] = v
        else:
            name, runs = k.split(RUNS_MARK, 1)
            if run_id in runs.split(RUNS_SEPARATOR):
                own[name] = v
    return fmu_parameters({**out, **own})


def parameters_of_a_new_run(params: dict[str, object]) -> dict[str, object]:
    """The FMU parameters a run outside the campaign is simulated with: those applied to every
    run, without those applied to some of the campaign's runs only (for_runs: a run's lug phase),
    ties given as the FMU variables they set (fmu_parameters)."""
    return fmu_parameters({k: v for k, v in params.items() if RUNS_MARK not in k})


def fmu_parameters(params: dict[str, object]) -> dict[str, object]:
    """``params`` as the FMU takes them: each tied extension parameter (ExtParam.sets) replaced
    by the FMU variables it sets, every one given its value (keeping the runs it is applied to,
    for_runs); every other entry as it is.  Raises ValueError where a tied variable is also
    given a different value of its own (two values for one variable: no model is meant)."""
    ties = {e.name: e.sets for c in CANDIDATES.values() for e in c.params if e.sets}
    out = {k: v for k, v in params.items() if unqualified(k) not in ties}
    for k, v in params.items():
        name = unqualified(k)
        for variable in ties.get(name, ()):
            key = variable + k[len(name):]
            if key in out and out[key] != v:
                raise ValueError(f"'{key}' is given {out[key]} and, through the tied parameter '{k}', {v}")
            out[key] = v
    return out


@dataclass(frozen=True)
class ExtParam:
    """One extension parameter: its name (the FMU variable's, unless it is a tie), start value
    and bounds.  It is searched as itself (bounded trust-region least squares keeps the
    finite-difference steps inside the bounds).  A tie (``sets`` given) is one fitted value for several FMU variables: ``name`` names the
    parameter in the fit and its results, and the FMU is given each variable of ``sets`` at
    its value (fmu_parameters)."""

    name: str
    start: float
    lower: float = -np.inf
    upper: float = np.inf
    sets: tuple[str, ...] = ()


@dataclass(frozen=True)
class Candidate:
    """A model extension the analysis can propose, and the physical cause it stands for."""

    name: str
    cause: str
    params: tuple[ExtParam, ...]
    fixed: tuple[tuple[str, float], ...] = ()
    needs_terrain: bool = False
    #: coarse starting points tried before least squares (for landscapes that are flat at the
    #: neutral point or rough): each a tuple of (name, value) pairs overriding the starts
    grid: tuple[tuple[tuple[str, float], ...], ...] = ()
    #: (name, neutral value, tolerance): the extension acts only if one of these parameters is
    #: further than its tolerance from neutral.  A fit that leaves them all there is the base
    #: model with refitted soil, and cannot name a cause (on the terrain run, a tiny soil change
    #: can move the residual by a few percent).
    active: tuple[tuple[str, float, float], ...] = ()
    #: if > 0, every grid point is refined by a least-squares fit of this many evaluations (on
    #: the drawbar runs) before the best goes on, instead of being ranked by its cost as is
    short_fits: int = 0
    #: whether the terrain-registration parameters are refined by least squares on the terrain
    #: run after the coarse search (False: the best start is kept as it is)
    refine_terrain: bool = True
    #: whether the fit is also started from the paper's initial soil (PAPER_INITIAL), not only
    #: from the base optimum, the better kept (fitting.better_of_two_fits).  The base fit bends
    #: the soil to absorb the hidden effect, and an extension's fit started there can stay in
    #: that basin: on synthetic multi-pass campaigns the base fit halved k_h and eta, and from
    #: there the multi-pass fit found half the true rut and stiffening, with 3.6 times the
    #: drawbar training error of the fit from the paper's start.
    soil_restart: bool = False
    #: whether the cause makes the traction, and the drive torque, ripple with the wheel angle at a
    #: few to a few tens per revolution (lugs entering the soil one by one): the periodic test's
    #: ripple (juno.periodic_structure) is then evidence for it over a tied cause that makes none
    #: (a gear's mesh ripples at hundreds per wheel revolution, beyond what the test scans)
    ripples_with_wheel_angle: bool = False

    @property
    def is_registration(self) -> bool:
        """Whether every parameter of the extension is a terrain-registration offset (no physical
        parameter: the registration is measured kinematically and judged on the measured pose)."""
        return all(e.name.startswith("terrain.") for e in self.params)

    def acts(self, params: dict[str, float]) -> bool:
        """Whether the extension is switched on at ``params`` (where it is applied to some runs
        only, for_runs: on any of them)."""
        return any(abs(params.get(k, v) - v) > tol for n, v, tol in self.active for k in self._named(params, n))

    def switched_off(self, params: dict[str, float]) -> dict[str, float]:
        """``params`` with this extension at its neutral setting (everything else kept)."""
        return {**params, **{k: v for n, v, _tol in self.active for k in self._named(params, n)}}

    def parameters_in(self, params: dict[str, float]) -> int:
        """How many parameters the extension adds in the fit ``params``: each of its parameters
        once for every group of runs ``params`` applies it to (for_runs), and once where it is
        applied to every run (or not set); a parameter the extension fits only where the campaign
        calls for it (named in ``active`` alone: the lugs' ripple, ripple_nuisance.with_lug_ripple)
        once for every group of runs ``params`` gives it to, and not at all where it gives none."""
        names = {unqualified(e.name) for e in self.params}
        optional = {n for n, _v, _tol in self.active} - names
        count = {n: sum(1 for k in params if unqualified(k) == n) for n in names | optional}
        return sum(max(1, count[n]) for n in names) + sum(count[n] for n in optional)

    def owns(self, name: str) -> bool:
        """Whether ``name`` (an FMU name, or one applied to some runs) is one of the extension's."""
        return any(unqualified(name) == unqualified(e.name) for e in self.params)

    @staticmethod
    def _named(params: dict[str, float], name: str) -> list[str]:
        """The entries of ``params`` that set FMU parameter ``name`` (for every run, or for some,
        for_runs); [name] when none does (it is then at its neutral setting)."""
        found = [k for k in params if unqualified(k) == name]
        return found or [name]


CANDIDATES: dict[str, Candidate] = {c.name: c for c in (
    # Starts are at each extension's neutral setting (bounded linear parameters, so the
    # finite-difference steps stay inside), and every fit begins at the base model; a soil
    # patch needs a slight contrast for its position to have a gradient.
    Candidate("soil_patch", "soil stiffness and strength vary over the test area",
              (ExtParam("soilPatch.x", 2.5), ExtParam("soilPatch.y", 0.0),
               ExtParam("soilPatch.radius", 1.0, 0.2, 5.0),
               ExtParam("soilPatch.khFactor", 0.97, 0.1, 10.0),
               ExtParam("soilPatch.strengthFactor", 0.99, 0.1, 10.0)),
              active=(("soilPatch.khFactor", 1.0, 0.02), ("soilPatch.strengthFactor", 1.0, 0.02)),
              short_fits=4),
    # Multi-pass is flat at its neutral point (with no rut, the stiffening has no gradient):
    # it starts with half the rut on moderately compacted soil.
    Candidate("multipass", "rear wheels roll in the front wheels' rut on compacted soil",
              (ExtParam("multipass.rutFraction", 0.5, 0.0, 1.0),
               ExtParam("multipass.khFactor", 1.3, 0.2, 10.0)),
              active=(("multipass.rutFraction", 0.0, 0.02),),
              grid=tuple((("multipass.rutFraction", r), ("multipass.khFactor", k))
                         for r in (0.5, 1.0) for k in (1.0, 1.5, 2.0, 3.0)),
              soil_restart=True),
    Candidate("slip_sinkage", "sinkage grows with slip as the wheel digs in",
              (ExtParam("slipSinkage.coefficient", 0.0, 0.0, 20.0),),
              active=(("slipSinkage.coefficient", 0.0, 0.02),), soil_restart=True),
    # The thrust gain raises the traction limit, which the shear nears only at high slip: at the
    # slips of a drawbar campaign the shear modulus K_vx takes up most of what a thrust gain
    # does, so from no gain the loss is nearly flat along it and least squares stops in the
    # basin where K_vx and the lug height absorb the thrust.  The coarse search also tries gains
    # of a half and one, from which the fit descends into the other basin when it is lower (on a
    # campaign whose lugs pulse the thrust, the true grouser's drawbar training objective was
    # 3.46; the fit from no gain stopped at 3.72, with a gain of 0.02 and lugs 5 mm too high; from
    # the grid it reached 3.51, with the lugs' height within 1 mm of the truth).
    # When the drive torques ripple at a lug count, the candidate also carries that ripple, its
    # amplitude fitted (ripple_nuisance.with_lug_ripple): lugs make it, and the soil absorbs their
    # mean thrust so well that on some campaigns the ripple is the lugs' only mark.
    Candidate("grouser", "lugs shear the soil at a larger radius and add thrust beyond the Mohr-Coulomb limit",
              (ExtParam("grouser.thrustGain", 0.0, 0.0, 3.0), ExtParam("grouser.lugHeight", 0.0, 0.0, 0.1)),
              active=(("grouser.thrustGain", 0.0, 0.01), ("grouser.lugHeight", 0.0, 0.001),
                      ("grouser.rippleAmplitude", 0.0, 0.01)), soil_restart=True,
              grid=((("grouser.thrustGain", 0.5),), (("grouser.thrustGain", 1.0),)),
              ripples_with_wheel_angle=True),
    # A drivetrain's losses in their standard form: a load-dependent part, a fraction of the
    # torque (gear mesh), and a no-load part, a Coulomb drag (seals, bearings, chain), the same
    # on both sides (one tied value for drive.frictionLeft and drive.frictionRight: the two
    # drivetrains are alike, and a one-sided drag is a fault, not a loss of the design).  A
    # fraction alone cannot follow a constant drag over drawbar runs at different loads.  No
    # viscous term: a drawbar run holds its spin nearly constant, so there a viscous drag is a
    # constant torque like the Coulomb one, and a campaign's runs at one throttle spin within
    # 0.3-0.45 rad/s of each other, so a viscous drag of 8 N m s/rad departs from the best
    # constant drag by 1-2 N m, under the drive torque's 3 N m noise scale.  Fitted beside the
    # two on campaigns with such a drag, it bought 0.7-2.4 % of held-out gain, less than the
    # 3 % a parameter is charged (judging.GAIN_MIN).
    # Both are linear in the torque they take and start at neutral (no grid).  The Coulomb
    # drag acts beyond 0.5 N m, a sixth of the drive torque's noise scale and what the
    # fraction's 0.005 is on the campaigns' 100-200 N m drive torques; it is bounded at 100 N m,
    # a quarter of the drive's torque limit (drive.torqueMax, 400 N m): a drive whose seals and
    # bearings took that much would spend a quarter of its torque turning its wheels in the air.
    Candidate("drivetrain_loss", "part of the measured motor torque is lost before the wheels",
              (ExtParam("drive.lossFraction", 0.0, 0.0, 0.9),
               ExtParam("drive.friction", 0.0, 0.0, 100.0, sets=("drive.frictionLeft", "drive.frictionRight"))),
              active=(("drive.lossFraction", 0.0, 0.005), ("drive.friction", 0.0, 0.5)), soil_restart=True),
    # The rover's mass as the campaign states it (rover.mass, the FMU's default unless the
    # manifest's rover entry gives one) is an input of every replay, and a rover heavier or
    # lighter than that (instruments or ballast nobody logged, a mis-weighed rover) sinks,
    # resists and climbs as no soil of the stated rover does: its weight scales the normal loads
    # on the drawbar runs and the climbing torque on the terrain runs alike, which a soil refit
    # cannot follow on both.  One parameter, the mass beyond the stated one (rover.payload, at the
    # chassis's centre of gravity), linear near 0, so the fit starts at neutral; it acts beyond
    # 2 kg (0.6 % of the Juno's 318 kg, what a platform scale resolves).  Its bounds are the
    # stated mass's (starts.payload_for_the_rover): down to half the rover, up to twice it.
    Candidate("payload", "the rover's mass is not the stated one: a payload nobody logged, or a mis-weighed rover",
              (ExtParam("rover.payload", 0.0, -150.0, 300.0),),
              active=(("rover.payload", 0.0, 2.0),), soil_restart=True),
    # The registration is kinematic (juno.registration: the scan against the measured height,
    # pitch and roll on the terrain runs' training blocks, no simulation) and judged on the
    # held-out blocks the same way (starts.registration_evidence, judging.judge).  These six
    # parameters (a shift, a raise, a turn, and a tilt in its small-angle form: a plane added to
    # the scan's heights) move every terrain run's
    # scan; a campaign with several scans gets them once per
    # scan it moves, applied to that scan's runs (starts.registration_candidate).  Refined by
    # simulation, it would also fit what the soil model gets wrong on the terrain run (a turn of
    # the scan can mimic a grouser's extra climbing thrust), so it is not refined; nor is it
    # rejected by the replay's training error, which also carries the soil model's error.
    Candidate("terrain_offset", "the scanned terrain is misregistered against the real one",
              (ExtParam("terrain.offsetX", 0.0), ExtParam("terrain.offsetY", 0.0),
               ExtParam("terrain.offsetZ", 0.0), ExtParam("terrain.offsetYaw", 0.0),
               ExtParam("terrain.slopeX", 0.0), ExtParam("terrain.slopeY", 0.0)),
              needs_terrain=True,
              active=(("terrain.offsetX", 0.0, 0.01), ("terrain.offsetY", 0.0, 0.01), ("terrain.offsetZ", 0.0, 0.003),
                      ("terrain.offsetYaw", 0.0, 0.003), ("terrain.slopeX", 0.0, 0.001),
                      ("terrain.slopeY", 0.0, 0.001)),
              refine_terrain=False),
)}


def combined(first: Candidate, second: Candidate) -> Candidate:
    """The model with both extensions (for the second round: a further cause on top of the first).
    Named after ``second``; only ``second``'s coarse grid is searched (``first`` starts at its
    fitted values).  The combination is not restarted from the paper's soil by itself: the
    second round decides that for the pair (search.second_round)."""
    return Candidate(second.name, second.cause, first.params + second.params, first.fixed + second.fixed,
                     first.needs_terrain or second.needs_terrain, second.grid, second.active, second.short_fits,
                     first.refine_terrain and second.refine_terrain)


def makes_ripple(name: str) -> bool:
    """Whether a cause, or any cause of a model named "a+b", makes the drive torque ripple with the
    wheel angle (Candidate.ripples_with_wheel_angle)."""
    return any(n in CANDIDATES and CANDIDATES[n].ripples_with_wheel_angle for n in name.split("+"))
