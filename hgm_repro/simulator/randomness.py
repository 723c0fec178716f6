"""The simulator's random draws, handed out for the whole batch of envs.

The physics (`highway.py`) asks for uniform draws over every env at once and never sees who owns
which env. Behind that sits grouped training (`hgm_repro.learner.grouped`): one simulator can hold
the envs of several training members, one seed each, in contiguous blocks, and each block must draw
its traffic from its own member's generator only, so that a member meets the same traffic alone or
in any group. Two rules keep it so:

- a block's draws come from its member's generator, in the order a solo simulator would make them;
- where a solo simulator skips its draws (no env needs a reset, no vehicle waits to come back), the
  member's block draws nothing either (its rows are zeros and go unused): `Draws`.

On a CPU grouping earns nothing per member (one member alone trains as fast as in a group), and
here it costs a Python loop over members, zero padding and one host read per masked draw. It pays
on a GPU, where one small batch of envs leaves most of the chip idle; this module is where its cost
is kept, and with one seed every draw is a single `torch.rand` on one generator.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch


class TrafficRandomness:
    """The generators of `n_envs` envs: one seed, or one seed per training member of a group."""

    def __init__(self, seed: int | Sequence[int], n_envs: int, device: torch.device):
        seeds = [int(seed)] if isinstance(seed, int) else [int(s) for s in seed]
        if not seeds or n_envs % len(seeds):
            raise ValueError(f"seed={list(seeds)!r} is not allowed with n_envs={n_envs}: need one seed, or one seed "
                             f"per member with n_envs a multiple of their number")
        self.n_envs = n_envs
        self.device = device
        self.member_envs = n_envs // len(seeds)
        self.generators = []
        for member_seed in seeds:
            generator = torch.Generator(device=device)
            generator.manual_seed(member_seed)
            self.generators.append(generator)

    @property
    def generator(self) -> torch.Generator:
        """A solo simulator's one generator (what evaluation, the Gymnasium envs and drivers seed and draw from)."""
        return self.generators[0]

    @property
    def n_members(self) -> int:
        return len(self.generators)

    def rand(self, *shape: int) -> torch.Tensor:
        """[n_envs, *shape] uniform draws in [0, 1), every env drawing."""
        return self.draws().rand(*shape)

    def draws(self, envs: torch.Tensor | None = None) -> Draws | None:
        """Draws for the envs where `envs` ([n_envs, ...] bool) has a True (every env when None);
        None when no member's block has one, as a solo simulator would then skip its draws."""
        if envs is None:
            return Draws(self, [True] * self.n_members)
        drawing = self._members_with(envs)
        return Draws(self, drawing) if any(drawing) else None

    def _members_with(self, envs: torch.Tensor) -> list[bool]:
        """Per member: whether any of its envs has a True in `envs`."""
        return envs.reshape(self.n_members, -1).any(1).tolist()


class Draws:
    """Uniform draws for the members whose envs need them; the other members' rows are zeros."""

    def __init__(self, randomness: TrafficRandomness, drawing: list[bool]):
        self.randomness = randomness
        self.drawing = drawing

    def rand(self, *shape: int) -> torch.Tensor:
        """[n_envs, *shape] uniform draws, each block of envs from its member's generator."""
        r = self.randomness
        if r.n_members == 1:
            return torch.rand(r.n_envs, *shape, generator=r.generator, device=r.device)
        return torch.cat([torch.rand(r.member_envs, *shape, generator=generator, device=r.device) if drawing
                          else torch.zeros(r.member_envs, *shape, device=r.device)
                          for generator, drawing in zip(r.generators, self.drawing, strict=True)])

    def rand_rows(self, rows: torch.Tensor, *shape: int) -> torch.Tensor:
        """[len(rows), *shape] uniform draws for the envs `rows` (ascending), each from its env's member."""
        r = self.randomness
        if r.n_members == 1:
            return torch.rand(rows.numel(), *shape, generator=r.generator, device=r.device)
        counts = torch.bincount(rows // r.member_envs, minlength=r.n_members).tolist()
        return torch.cat([torch.rand(count, *shape, generator=generator, device=r.device)
                          for generator, count in zip(r.generators, counts, strict=True)])

    def narrow(self, envs: torch.Tensor) -> torch.Tensor | None:
        """Members with no True in `envs` ([n_envs] bool) stop drawing for good, as a solo simulator
        returns there; `envs` without the rows of members that no longer draw (None: no member draws).
        Those rows hold zeros, not draws, and a solo simulator would not have gone on to use them."""
        r = self.randomness
        now = r._members_with(envs)
        self.drawing = [was and still for was, still in zip(self.drawing, now, strict=True)]
        if not any(self.drawing):
            return None
        if all(self.drawing):
            return envs
        return envs & torch.tensor(self.drawing, device=r.device).repeat_interleave(r.member_envs)
