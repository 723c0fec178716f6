"""The learner: Dueling DQN with prioritized experience replay on TorchRL (Selected Algorithm, Table 4).

`train(job, checkpoint_dir, log) -> Path` trains `job.model` (`job`: the typed `JobConfig` that
`hgm_repro.contracts.schema.check_config` builds) on the training traffic and returns the final checkpoint
(`checkpoint_dir/final.pt`); `train_group(jobs, checkpoint_dirs, logs)` trains the seeds of one model in one
process, in the same loop (`loop.py`: a solo run is a group of one). The parts are TorchRL's: `Collector` over
the batched env (warm-up through its `init_random_frames`), `TensorDictPrioritizedReplayBuffer` on a
`LazyTensorStorage` (priorities |TD error|, alpha `per_alpha`, beta annealed by `LinearScheduler`),
`QValueActor` + `EGreedyModule`, `DQNLoss` with a delayed target and `HardUpdate` (or `SoftUpdate`). When
TorchRL's compiled extension does not load (its 0.14.1 wheel against torch 2.13 CPU), the sampler's segment
trees are replaced by pure-torch ones (`priority_trees.py`); the sampler itself stays TorchRL's.

Checkpoints and resume
----------------------
`checkpoint_dir/last.pt` is written every `logging.checkpoint_every` env steps and when a stop
signal (`hgm_repro.contracts.interrupts`) ends the run between two batches, `final.pt` at the end
(which then replaces `last.pt`: a finished training keeps its full state once); each write goes to
a temporary file first and is renamed into place, so a run killed while writing keeps the previous
checkpoint. `best.pt` (validation on) holds only what evaluation loads. A checkpoint holds:

- the online network, the target network (inside the loss module's state) and Adam's state;
- env steps done, gradient updates done, the epsilon-greedy module (current epsilon), the PER beta
  schedule position, the target-update counter, the fractional update credit;
- the torch / numpy / python RNG states and the simulator's generator;
- the training identity (`hgm_repro.contracts.train_key.training_config`: model name and network,
  observation, learner, simulator, training traffic, seed) and its `train_key`. A checkpoint from
  another model or config is refused with a message naming both and listing the differing keys;
- the replay buffer, only when it is small (`runtime.checkpoint_buffer_max_mb`, default 256 MB).
  A transition holds both observations of both streams in uint8: the smoke preset's buffer is
  stored, the quick preset's (about 600 MB) and the paper's (about 3.4 GB at 84x84, 4 frames) are not.

Calling `train` again with the same `checkpoint_dir` resumes from `last.pt` and stops at the same
total env step count as an uninterrupted run (`learner.total_steps`, rounded up to whole batches of
`learner.n_envs` steps). What a resume does not restore: the traffic itself (every env starts a
fresh episode, drawn from the restored generator), and, when the buffer was not stored, the replay
contents: the restored epsilon-greedy policy then refills `learner.warmup_steps` transitions before
updates start again (these count as env steps, so such a run makes about warmup_steps / update_every
fewer updates than an uninterrupted one). If `final.pt` exists, `train` returns it at once.

A NaN or infinite loss stops the run with `NonFiniteLossError`; checkpoints already written and
metrics already logged stay.
"""

from ..models.networks import param_counts
from .loop import train, train_group
from .member import NonFiniteLossError

__all__ = ["NonFiniteLossError", "param_counts", "train", "train_group"]
