"""The learner study's arms: each a list of Hydra overrides on the quick preset, stated in full so that
an arm's meaning does not move when the preset does; and the reference hosts each seed is tested with.
Read by `learner_study.py` (which runs them) and `study_report.py` (which reports them)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]


def arm_job(arm: str, seed: int) -> Any:  # -> hgm_repro JobConfig (imported late: a script's --help stays fast)
    """The validated job of `arm` on `seed` as the study runs it (the quick preset, the training traffic):
    its train_key names the training's checkpoint folder, and its scenario is where the study tests."""
    from hydra import compose, initialize_config_dir

    from hgm_repro.contracts.conf_dir import CONF_DIR
    from hgm_repro.contracts.schema import check_config

    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return check_config(compose("config", overrides=["experiment=quick", f"seed={seed}", "scenario=train",
                                                         *ARMS[arm]]))

# The camera the study proposes: aimed 15 degrees down (the horizon at about a third of the image
# instead of half), a 60 degree field (a car 15 m ahead 1.7x larger than at 90 degrees, adjacent
# lanes still in view from 6 m on), at a dash camera's 1.2 m, cars 1.5 m tall (a saloon).
CAMERA = ["observation.camera_pitch_deg=15", "observation.camera_fov_deg=60", "observation.camera_height=1.2",
          "observation.vehicle_height=1.5"]
DQN_FIXES = ["learner.n_step=3", "learner.double_dqn=true", "learner.loss_function=smooth_l1"]
R20 = [*DQN_FIXES, "eval.val_envs=32"]
# The issue-20 combination (arm r20_all, the quick preset since): the base of the arms that follow it.
R20_ALL = [*R20, "learner.random_lane_change_share=0.1", "learner.eps_floor=0.01", "learner.eps_floor_steps=30000",
           "learner.lr=0.0001", "learner.adam_eps=0.00015", "learner.target_tau=0.005", "learner.ema_decay=0.999"]

# The quick preset's values that the issue-20 preset changed, as they were before: every arm below
# was defined on them, and states them, so that its meaning does not move with the preset.
QUICK_BEFORE_R20 = ["learner.lr=0.00025", "learner.adam_eps=1e-08", "learner.eps_floor=0.0",
                    "learner.eps_floor_steps=0", "learner.random_lane_change_share=0.4", "learner.target_tau=0.0",
                    "learner.ema_decay=0.0", "eval.val_envs=8"]


def on_preset_before_r20(overrides: list[str]) -> list[str]:
    """`overrides` on top of QUICK_BEFORE_R20 (an arm's own value of a key replaces the old one)."""
    merged = {o.split("=", 1)[0]: o for o in QUICK_BEFORE_R20}
    merged.update({o.split("=", 1)[0]: o for o in overrides})
    return list(merged.values())


# Every arm states each learner option it studies, so that its meaning does not move when the
# preset does (the quick preset adopted DQN_FIXES from this study, then the r20_all settings).
_ARMS: dict[str, list[str]] = {
    # The quick preset before the study: the paper's one-step plain DQN with the L2 loss.
    "base": ["learner.n_step=1", "learner.double_dqn=false", "learner.loss_function=l2"],
    "huber_double": ["learner.n_step=1", "learner.loss_function=smooth_l1", "learner.double_dqn=true"],
    "nstep": DQN_FIXES,
    "nstep_camera": DQN_FIXES + CAMERA,
    "nstep_camera_4frames": DQN_FIXES + CAMERA + ["observation.frame_stack=4"],
    "nstep_camera_gamma95": DQN_FIXES + CAMERA + ["learner.gamma=0.95"],
    # Seeds 0-3 of the first grid run with the nstep preset: only one host of four learned to stop
    # crashing by 80k steps (training episodes ended in a crash almost every time, at epsilon 0.05).
    # Two suspects: a 100-step horizon (gamma 0.99) whose values dwarf the crash and take long to
    # propagate, and exploration crashes (5% random actions, lane changes into occupied lanes).
    "nstep_gamma95": DQN_FIXES + ["learner.gamma=0.95"],
    "nstep_gamma95_eps01": DQN_FIXES + ["learner.gamma=0.95", "learner.eps_end=0.01"],
    "nstep_eps01": DQN_FIXES + ["learner.eps_end=0.01"],
    # Twice the budget: does the host that learns at 50-60k steps on some seeds learn on all?
    "nstep_160k": DQN_FIXES + ["learner.total_steps=160000"],
    # Not crashing pays only over a long horizon: at Table 2's rewards, driving at 75 km/h and
    # crashing after 30 decisions earns more than 30 decisions at 50 km/h, and loses only over
    # the ~100 decisions that gamma 0.99 weighs (gamma 0.95 made crashing the better deal). That
    # value travels back n decisions per target update, so longer n-step windows or more frequent
    # target updates should make the host learn it sooner.
    "nstep10": ["learner.n_step=10", "learner.double_dqn=true", "learner.loss_function=smooth_l1"],
    "nstep_target250": DQN_FIXES + ["learner.target_update_steps=250"],
    # Seeds 101-102 showed why the host races: under gamma 0.99 racing at 75 km/h and crashing
    # after 40 decisions is worth more (70) than a whole episode at 52 km/h (63), although the
    # episode return says the opposite. A horizon as long as the episode (gamma 0.995: 200
    # decisions; 0.998: 500) makes safe driving the better deal for the learner too (0.998: 132
    # against 79). They come with the two settings that helped on seed 101 (final epsilon 0.01,
    # target update every 250 steps), since a longer horizon needs more target updates to carry
    # the crash's cost back.
    "g995_eps01_t250": DQN_FIXES + ["learner.gamma=0.995", "learner.eps_end=0.01",
                                    "learner.target_update_steps=250"],
    "g998_eps01_t250": DQN_FIXES + ["learner.gamma=0.998", "learner.eps_end=0.01",
                                    "learner.target_update_steps=250"],
    # Neither horizon learned by 80k steps (seed 101: gamma 0.998 crashed in every test episode,
    # 0.995 earned 156 with 0.27 crashes): a longer horizon also takes longer to learn. The other
    # way to make racing the worse deal is a dearer crash, for the learner only (tests still score
    # Table 2): at 5 x R_c = -100 and gamma 0.99, racing at 75 km/h with a crash after 40
    # decisions is worth 16, safe driving at 52 km/h 63; racing wins only if its crashes are over
    # 65 decisions apart.
    "nstep_crash5": DQN_FIXES + ["learner.collision_weight=5"],
    # What budget reaches the bar: the preset's settings trained four times longer, with best.pt
    # chosen by validation every 20k steps as the preset does. Epsilon reaches its floor at 30k
    # steps whatever the total; the importance-sampling exponent anneals over the whole run, so
    # the first 80k steps are not the preset's run.
    "nstep_320k": DQN_FIXES + ["learner.total_steps=320000"],
    # The two settings that each helped on seed 101 (fewer exploration crashes; the crash's cost
    # carried back four times as often), together, at the preset's budget.
    "nstep_eps01_t250": DQN_FIXES + ["learner.eps_end=0.01", "learner.target_update_steps=250"],
    # At 320k steps the greedy policy swung between checkpoints instead of settling: a smaller
    # step size (1e-4, 0.4x the preset's) is the plain DQN remedy, given twice the steps to make up
    # for the slower learning.
    "nstep_lr1e4_160k": DQN_FIXES + ["learner.lr=0.0001", "learner.total_steps=160000"],
    # Issue 20, on the fixed simulator (a crash no longer pays R_o): the preset ("nstep") is the
    # baseline, and each arm below adds one change to it, with 32 validation envs so that one crash
    # moves a validation mean by 0.6 instead of 2.4 (best.pt is chosen more reliably).
    # Exploration that does not crash on its own: an IDM lane keeper with 5% uniform random actions
    # crashed in 41% of its episodes, all from random lane changes; here random actions change lanes
    # 1 time in 10 instead of 2 in 5, and epsilon falls on from 0.05 to 0.01 over 30k more steps.
    "r20_explore": R20 + ["learner.random_lane_change_share=0.1", "learner.eps_floor=0.01",
                          "learner.eps_floor_steps=30000"],
    # A cooler optimiser: the step size of Rainbow-style agents' order (lr 1e-4, 0.4x the preset's,
    # the one lever that reached the bar on a tuning seed) with Adam's eps 1.5e-4.
    "r20_adam": R20 + ["learner.lr=0.0001", "learner.adam_eps=0.00015"],
    # Polyak target updates instead of a hard copy every 1k steps: tau 0.005 per update (one update
    # per 4 steps) averages over about 800 env steps, so the target never jumps.
    "r20_polyak": R20 + ["learner.target_tau=0.005"],
    # The three together, with the moving average of the online weights kept for the test (ema.pt).
    "r20_all": R20_ALL,
    # The combination at twice the budget (the confirmation runs up to 160k steps): at 80k
    # steps its training episodes still crashed 0.3-0.8 times each, and the final network tested
    # below best.pt, so the host was still learning when the run stopped.
    "r20_all_160k": R20_ALL + ["learner.total_steps=160000"],
    # The arms below add one change each to r20_all (the preset since), keeping what helped.
    # A memory that holds the whole run (80k transitions, frames stored once: about 600 MB), so that
    # the high-speed crashes of early training stay in it once the greedy host has slowed down.
    "r20_memory": R20_ALL + ["runtime.replay_frames=true", "learner.buffer_size=80000"],
    # What the HGM shows (the published grid keeps the paper's): the host visible at every speed
    # (at 60 km/h, where every host starts, the paper's formula writes the empty cell's 0), a window
    # reaching 80 m ahead (shedding 26 km/h takes about 57 m; D_r is 40 m), and the enriched variant
    # (occupancy and host channels), which answers the first too.
    "r20_host_cell": R20_ALL + ["observation.hgm_host_cell=own_range"],
    "r20_ahead": R20_ALL + ["observation.hgm_ahead=80"],
    "r20_enriched": R20_ALL + ["model.streams.hgm=enriched"],
    # The enriched HGM's best.pt met the bar on 3 of 5 seeds at 80k steps with 0.04 collisions per
    # episode (research/study.md section 10), missing on return, not safety; 160k steps gave r20_all's
    # validation a second chance at a good checkpoint (section 9). Section 11: best.pt met the bar on 4 of
    # 5 seeds (248 [219, 277], 0.09 collisions); with model=proposed_enriched it is experiment=quick160.
    "r20_enriched_160k": R20_ALL + ["model.streams.hgm=enriched", "learner.total_steps=160000"],
    # Issue 20's comparison methods on that preset (experiment=quick160): Min's image-only network and
    # the Coordinate network, whose streams have no HGM to enrich, trained with the same learner and budget.
    # Section 12: neither became safe (best.pt 0.44 and 0.39 collisions per episode; bar 0 and 1 of 5).
    "r20_min_160k": R20_ALL + ["model=min", "learner.total_steps=160000"],
    "r20_coordinate_160k": R20_ALL + ["model=coordinate", "learner.total_steps=160000"],
    # Their greedy validation peaked at 40-60k steps and then collapsed (section 12): a cooler step
    # (lr 5e-5, half the preset's), the first of the tuning the proposed host had and they did not.
    # Probed on seed 101 only (section 12): Min still collapsed after 40k steps, Coordinate barely learned.
    "r20_min_160k_lr5e5": R20_ALL + ["model=min", "learner.total_steps=160000", "learner.lr=0.00005"],
    "r20_coordinate_160k_lr5e5": R20_ALL + ["model=coordinate", "learner.total_steps=160000",
                                            "learner.lr=0.00005"],
    # What the camera shows: the r20_all host's crashes are mostly lane changes into slow unconnected
    # cars just ahead in the next lane, which only the camera shows (research/study.md section 9); at
    # 36x36 such a car sits at the image's edge as a few pixels. The paper's 84x84 with 4 frames.
    "r20_camera84": R20_ALL + ["observation.height=84", "observation.width=84", "observation.frame_stack=4"],
}
ARMS: dict[str, list[str]] = {arm: on_preset_before_r20(overrides) for arm, overrides in _ARMS.items()}


# The reference hosts the study tests on each tuning seed (no training, the same traffic): the bar
# (the human-driven host), the fair rule inside the host's own limits, and its lane-keeping half.
STUDY_REFERENCES = ("human", "idm_mobil_limits", "idm_limits")
