"""Model discovery: what the simulation gets wrong, why, and what fixing it gains.

1. Fit the base model (the paper's four soil parameters) on the *training*
   half of the drawbar runs' samples: alternate 4 s blocks of every run are
   training and held-out data (the model is simulated over the whole run,
   driven by the measured inputs; only the comparison is split).
2. Show the base model's residuals against time, position, slip and side.
3. Fit each candidate extension (CANDIDATES: its own
   parameters together with the four soil parameters refitted), on the
   training blocks.  Each starts at the base optimum; the physical ones with
   few parameters are also started from the paper's initial soil (the base fit
   bends the soil to absorb the hidden effect, and the extension's fit can stay
   in that basin); the drawbar runs' training blocks choose between the two
   fits, unless the fit they prefer lost the rover on the terrain replay
   (better_of_two_fits).  Every
   fit minimises a soft-L1 loss of the scaled residuals (fit_loss): squares
   up to about FIT_LOSS_SCALE sigma, linear beyond, so that the few seconds
   where a spin-following replay is on a knife edge (a rear wheel dropping
   into the rut, a wheel digging in at high slip) do not bend the soil.
   Every fit, and every comparison below, takes the IMU's mounting as a
   nuisance (sensor_offset.offset_free): the pitch residuals' mean over the
   drawbar runs' training blocks, one constant for the campaign, is taken off
   every pitch residual, so no cause is credited with what a mounting bias
   explains; what the models report, and the structure test reads, keep it.
4. Compare candidates on the held-out blocks of every run (the same data for
   all): the gain is the drop of the mean squared scaled residual (each
   capped at RESIDUAL_CAP^2: a replay that loses the rover says only that).  Physical
   extensions are fitted on the drawbar runs only, so the terrain run is a
   validation run for them, as in the paper (replayed following the measured
   spins or driven by the measured torque: whichever lets some fitted model, the
   base model or a candidate, fit its training blocks best; settle_terrain_drive).
   The registration is measured
   kinematically (juno.registration: the rover posed on the scan against the
   measured height, pitch and roll), one per scan on the training blocks of the
   terrain runs on that scan, and in the first round judged the same way on their
   held-out blocks (registration_evidence, HELD_OUT_RATIO; a scan whose evidence
   passes is moved by its own offsets, applied to its runs only: registration_candidate); on top of another cause it is judged like the others, since
   the kinematic model does not know that cause.  A gain counts as significant only when
   a paired test over held-out units (run, block, signal; on the units' mean
   squared-residual change, so time correlation inside a block is respected;
   changes under NEGLIGIBLE_CHANGE are ties; the Wilcoxon signed-rank test and the
   sign-flip test of the summed change, each at half the level: paired_z; on the
   terrain runs, whose open-loop replay drifts so that their blocks are not independent, the
   weaker of that and the replicas' test, the loss difference over its spread when every model
   is replayed on the same REPLICAS copies of the terrain runs with fresh sensor noise:
   terrain_replicas, judging.terrain_evidence) gives z > Z_MIN
   (Bonferroni-corrected over the kinds of run) on some kind of run and
   z > -Z_MIN on every kind, the relative gain over all held-out data
   exceeds GAIN_MIN per parameter the extension adds, the fitted
   extension is switched on (not at its neutral setting), and switching it off
   loses the gain by the same criteria.  The gain and z on each kind of run are
   reported.  The cause is the significant candidate with the largest gain
   less GAIN_MIN per parameter (penalised_gain), unless a runner-up with more
   parameters and a larger raw gain explains the held-out data significantly
   better than it, by the same paired test with the leader as the reference
   (head_to_head); or ``none``.  When the measured drive torques ripple with the
   wheel angle at a lug count (juno.periodic_structure), a leader whose cause makes
   no ripple gives the lead to a significant runner-up whose cause makes one, unless
   it explains the held-out data significantly better than that runner-up by the
   same paired test (ripple_maker_leads).  Candidates whose gain is within TIE_RATIO of
   the cause's are reported as equally good, each with the steady drawbar run
   at which its fit and the cause's differ most (tied_models_apart).
5. Look for a second cause: every other candidate (even one that did not
   help on its own: an unmodelled first cause can hide it) is refitted
   together with the first cause and judged against it by the same
   criteria; the causes are listed strongest (largest held-out gain) first.
   Two causes that both restart from the paper's soil are fitted together
   from there as well, and the fit with the lower training loss over every
   run is kept (training_objective).
   The model with both causes is then refitted once more from the paper's
   initial soil, and the better fit by fit_objective is reported
   (refit_from_paper_soil).  When the head-to-head test overturned the
   penalised ranking's leader, or a runner-up trails it by less than NEAR_TIE
   after the charge and the paired test does not prefer the leader to it
   (tie_settled), both get a second round, and the final models are
   compared by the rules of step 4 (choose_branch).  So does a runner-up
   within NEAR_TIE that fails significance by its soil alone (its soil at a
   bound of the search), unsettled; its final model must bring the soil
   back (first_cause_branches, branches_with_real_soil).

Every terrain run is replayed on the grid of its own scan.  The campaign needs at least one
drawbar run (the soil and every physical extension are fitted there); without a terrain run the
candidates that need one are left out.  A fit over which more than identify.MAX_FAILED_FRACTION
of the simulations failed, or whose fitted runs fail at its optimum, is a failed fit: the base
model's is an error (exit status 2), a candidate's is reported with ``status`` "failed" and never
named a cause.

It never reads ``truth.json``.

The modules, one concept each: ``candidates`` (the catalogue of extensions), ``problem`` (the data
and a model's residuals on it), ``fitting`` (one model's fit, the fit loss, two fits compared),
``sensor_offset`` (the IMU's mounting, a nuisance of every fit and judgement), ``starts`` (where a
candidate's search starts), ``terrain_drive`` (how the terrain runs are
replayed), ``terrain_replicas`` (the terrain runs with fresh sensor noise, the spread their
evidence is judged against), ``references`` (what a candidate is judged against), ``judging`` (the paired test, the
thresholds, the judge, ranking and head to head), ``search`` (the rounds and branches, and
diagnose()), ``assemble`` (the result's numbers), ``results`` (the typed results and their JSON)
and ``render`` (text, figures, the report's section).
"""

from __future__ import annotations

from ..registration import HELD_OUT_RATIO, HeldOutEvidence
from ..simulator import SOIL_PARAMETERS
from .assemble import per_signal_rms, residual_analysis
from .candidates import CANDIDATES, Candidate, ExtParam, combined, makes_ripple
from .fitting import (BASE_ITERATIONS, CANDIDATE_ITERATIONS, FIT_LOSS_SCALE, LOST_RATIO, SOIL_SEARCH_BOUNDS, FitResult,
                      better_of_two_fits, fit_candidate, fit_loss, fit_objective, loss_on, replayed, run_jobs,
                      training_objective)
from .judging import (GAIN_MIN, NEAR_TIE, NEGLIGIBLE_CHANGE, RESIDUAL_CAP, TIE_RATIO, Z_MIN, capped_square,
                      head_to_head, judge, leader_after_head_to_head, paired_z, passes, penalised_gain, ranked,
                      relative_gain, ripple_maker_leads, significant_but_for_its_soil, z_threshold)
from .problem import (BLOCK, DIAGNOSE_STEP, OUTPUT_INTERVAL, Problem, all_residuals, build_problem,
                      residuals_by_run, residuals_for, residuals_or_failure, run_kinds)
from .references import best_reference, on_reference_soil
from .render import apart_sentence, by_kind, duel_sentence, report_section, residual_figures, summary_lines
from .results import (Ablation, Baseline, CauseGain, Contender, Criteria, DiagnosisResult, Duel, ExtendedModel,
                      GainStep, JudgedCandidate, KinematicEvidence, NoCauseGain, PlotData, Ranked, ResidualAnalysis,
                      ScanRegistration, SignalGain, TiedPair, public_json)
from .search import (branches_with_real_soil, choose_branch, diagnose, first_cause_branches, refit_from_paper_soil,
                     second_round, tie_settled, tied_models_apart, wheel_angle_ripple)
from .sensor_offset import MOUNTED_SIGNALS, offset_free
from .starts import patch_grid, patch_start, registration_candidate, registration_evidence, registration_start
from .terrain_drive import choose_terrain_drive, drive_problems, settle_terrain_drive
