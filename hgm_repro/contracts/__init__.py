"""The ground floor: what every other part agrees on, and nothing that runs.

The typed config schema and the simulator's and observation builders' validated configs, where the
configs live, the errors bad input raises, the training identity (`train_key`), the checkpoint
format, stop signals, and the names of metrics, files and seed offsets. Nothing here builds a
network, opens a store or steps a simulator, so every floor above may import it and it imports
none of them; importing it does not load torch (only `checkpoint` does, when used).
"""
