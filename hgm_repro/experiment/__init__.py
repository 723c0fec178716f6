"""The experiment layer: the Hydra job (train once, evaluate many), its typed schema, the training
identity, checkpoints, MLflow tracking and stop signals.

Kept import-free so that the learner and evaluation can reach `checkpoint` and `interrupts`
without pulling in MLflow or Hydra.
"""
