"""The networks (the paper's two-stream Dueling network and its parts) and their builders: what the
learner trains and evaluation loads. `baselines/` adds Min's and the Coordinate networks."""
