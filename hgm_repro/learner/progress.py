"""Where a training stands: the counters its checkpoints record and a resume starts from."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass
class Progress:
    """Env steps (per member), gradient updates, the fraction of an update earned but not yet made,
    and the seeds trained together (None alone). Every member of a group is at the same point."""

    env_steps: int = 0
    updates: int = 0
    update_credit: float = 0.0
    group: list[int] | None = None

    @classmethod
    def from_checkpoint(cls, resume: dict[str, Any] | None, group: list[int] | None = None) -> Progress:
        """The point a checkpoint (`None`: none, a fresh start) left off at; `group` is this run's, not the
        checkpoint's (a resumed member may train with other seeds than before)."""
        if resume is None:
            return cls(group=group)
        return cls(int(resume["env_steps"]), int(resume["updates"]), float(resume["update_credit"]), group)

    def to_checkpoint(self) -> dict[str, Any]:
        """The counters under the checkpoint's keys (`grouped_with` only for a group)."""
        return {"env_steps": self.env_steps, "updates": self.updates, "update_credit": self.update_credit,
                **({"grouped_with": self.group} if self.group else {})}

    def earn_updates(self, env_steps: int, update_every: int) -> int:
        """The whole updates that `env_steps` more steps per member earn at one update every
        `update_every` steps; the fraction left carries over to the next batch."""
        self.update_credit += env_steps / update_every
        updates = 0
        # One unit at a time, as the credit has always been spent: taking the whole part at once can round otherwise.
        while self.update_credit >= 1.0:
            self.update_credit -= 1.0
            updates += 1
        return updates

    def crossed(self, steps_before: int, every: int) -> bool:
        """Whether the last batch, which began at env step `steps_before`, reached a multiple of `every`."""
        return self.env_steps // every > steps_before // every
