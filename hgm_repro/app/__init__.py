"""The top floor: the Hydra job (train once, evaluate many), the MLflow store and the sweep
callback. Nothing below imports it."""
