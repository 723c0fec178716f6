"""What the MLflow UI says in words: the experiment's description, a launch's, a training run's and an
evaluation run's (MLflow renders them as markdown), and a run's resolved config as `config.yaml`."""

from __future__ import annotations

from pathlib import Path

from omegaconf import OmegaConf

from ..contracts.schema import JobConfig
from .provenance import SOURCE_NAME

EXPERIMENT_DESCRIPTION = (
    "Runs of **hgm_repro**, the reproduction of Bai et al.'s Hyper-Grid Matrix driving-decision paper.\n\n"
    "Every top-level run is one launch of `python -m hgm_repro`: a sweep (`-m`) or a single job. Expand it "
    "to see the runs it made: trainings (tag `stage=train`, in the training traffic) and evaluations "
    "(`stage=eval`, one per model, test scenario and seed; each links to its training). A launch's "
    "description ends with the means over seeds of its evaluations.\n\n"
    "**Views** holds two views: *Evaluations grid* (every model, scenario and seed with its results) and "
    "*Training curves* (for the chart view). "
    "Figures, tables and the PDF report: `python -m analysis`."
)


def launch_description(kind: str, overrides: str, where: Path) -> str:
    """A launch's description: the command, where it ran, and what sits under it."""
    what, flag = ("A sweep", "-m ") if kind == "sweep" else ("A single job", "")
    command = f"{SOURCE_NAME} {flag}{overrides}".strip()
    return (f"{what}: `{command}`, launched in `{where}`. The trainings and evaluations it ran are the "
            "runs nested under it.")


def training_description(job: JobConfig, key: str, checkpoint_dir: Path) -> str:
    return (f"Training of **{job.model.name}** (seed {job.seed}) in the training traffic "
            f"(`{job.train_scenario.name}`) for {job.learner.total_steps} env steps, experiment preset "
            f"`{job.experiment.name}`, train_key `{key}`. Checkpoints in `{checkpoint_dir}`; the final network "
            "is also the MLflow model `model` of this run (`mlflow.pytorch.load_model`). Every evaluation of "
            "this training links here.")


def evaluation_description(job: JobConfig, how: str, training_link: str | None, checkpoint: Path | None) -> str:
    """`how` the network came to the job (trained, resumed, reused), `training_link` a markdown link to
    its training run (None for a non-learning host)."""
    scenario = job.scenario.name
    where = f"scenario {scenario}" if str(scenario).isdigit() else f"the `{scenario}` traffic"
    text = (f"Evaluation of **{job.model.name}** (seed {job.seed}) in {where}: {job.eval.test_steps} greedy "
            f"decisions over {job.eval.test_envs} envs, test traffic drawn from seeds no training uses.")
    if training_link is None:
        return text + " A non-learning host: nothing was trained."
    verb = {"reused": "reused from", "trained": "trained by", "resumed": "resumed by"}.get(how, "from")
    return text + f" The network ({checkpoint.name if checkpoint else '?'}) was {verb} {training_link}."


def results_sentence(means: dict[str, float]) -> str:
    parts = [f"{label} **{means[key]:.4g}**" for key, label in (
        ("eval/episode_return", "mean episode return"), ("eval/avg_speed_kmh", "speed (km/h)"),
        ("eval/collisions", "collisions per episode"), ("eval/episodes", "episodes")) if key in means]
    return "Results: " + ", ".join(parts) + "." if parts else ""


def config_yaml(job: JobConfig) -> str:
    """The resolved config as a run's `config.yaml`."""
    return OmegaConf.to_yaml(OmegaConf.create(job.resolved))
