"""The batched simulator as a TorchRL environment: batch size [n_envs], one TensorDict per step.

This is the fast path every experiment runs on; the Gymnasium env is a single-env convenience.
Observation keys depend on the model's streams (an env emits only what its model reads).
"""

from __future__ import annotations

import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Bounded, Categorical, Composite, OneHot, Unbounded
from torchrl.envs import EnvBase

from ..contracts.events import RECORDED_PER_EPISODE
from ..observations import ObservationBuilder, ObservationConfig
from ..simulator import N_ACTIONS, HighwaySimulator, ScenarioConfig, SimulatorConfig

REWARD_TERM_KEYS = ("speed", "collision", "dangerous", "lane_change", "overtake")


class HeterogeneousHighwayEnv(EnvBase):
    """TorchRL view of `HighwaySimulator` plus the observation builders.

    Extra outputs besides the observations: `episode` (per-episode metrics, valid where `done`)
    and `reward_terms` (Algorithm 2's terms, each on its own), so that training curves and tests
    can read them without another pass over the state.
    """

    def __init__(self, sim_cfg: SimulatorConfig, scenario: ScenarioConfig, obs_cfg: ObservationConfig,
                 n_envs: int, device: torch.device | str = "cpu", seed: int = 0):
        super().__init__(device=torch.device(device), batch_size=torch.Size([n_envs]))
        self.simulator = HighwaySimulator(sim_cfg, scenario, n_envs, device=device, seed=seed)
        self.observations = ObservationBuilder(self.simulator, obs_cfg)
        self.obs_cfg = obs_cfg
        self._make_specs()

    def _make_specs(self) -> None:
        n, d = self.batch_size[0], self.device
        obs = {}
        for key, (shape, dtype) in self.observations.specs().items():
            if dtype == torch.uint8:
                obs[key] = Bounded(low=0, high=255, shape=(n, *shape), dtype=torch.uint8, device=d)
            else:
                obs[key] = Unbounded(shape=(n, *shape), dtype=dtype, device=d)
        obs["episode"] = Composite({k: Unbounded(shape=(n,), device=d) for k in RECORDED_PER_EPISODE}, shape=(n,),
                                   device=d)
        obs["reward_terms"] = Composite({k: Unbounded(shape=(n,), device=d) for k in REWARD_TERM_KEYS},
                                        shape=(n,), device=d)
        self.observation_spec = Composite(obs, shape=(n,), device=d)
        self.action_spec = OneHot(N_ACTIONS, shape=(n, N_ACTIONS), device=d)
        self.reward_spec = Unbounded(shape=(n, 1), device=d)
        self.done_spec = Composite(
            {k: Categorical(2, shape=(n, 1), dtype=torch.bool, device=d) for k in ("done", "terminated", "truncated")},
            shape=(n,), device=d)

    def _zeros(self, keys: tuple[str, ...]) -> TensorDict:
        n = self.batch_size[0]
        return TensorDict({k: torch.zeros(n, device=self.device) for k in keys}, batch_size=[n], device=self.device)

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs) -> TensorDictBase:
        n = self.batch_size[0]
        mask = None
        if tensordict is not None and "_reset" in tensordict.keys():
            mask = tensordict.get("_reset").reshape(n).to(self.device)
        self.simulator.reset(mask)
        obs = self.observations.reset(mask)
        false = torch.zeros(n, 1, dtype=torch.bool, device=self.device)
        return TensorDict({**obs, "episode": self._zeros(RECORDED_PER_EPISODE),
                           "reward_terms": self._zeros(REWARD_TERM_KEYS),
                           "done": false, "terminated": false.clone(), "truncated": false.clone()},
                          batch_size=[n], device=self.device)

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        n = self.batch_size[0]
        action = tensordict.get("action")
        if action.dtype == torch.bool or action.shape[-1:] == (N_ACTIONS,):
            action = action.to(torch.long).argmax(-1)
        result = self.simulator.step(action.reshape(n))
        obs = self.observations.step()
        episode = TensorDict({k: result.episode[k].float() for k in RECORDED_PER_EPISODE}, batch_size=[n],
                             device=self.device)
        terms = TensorDict({k: v.float() for k, v in result.terms.as_dict().items()}, batch_size=[n],
                           device=self.device)
        return TensorDict({**obs, "episode": episode, "reward_terms": terms,
                           "reward": result.reward.float().unsqueeze(-1),
                           "done": result.done.unsqueeze(-1), "terminated": result.terminated.unsqueeze(-1),
                           "truncated": result.truncated.unsqueeze(-1)},
                          batch_size=[n], device=self.device)

    def _set_seed(self, seed: int | None) -> None:
        if seed is not None:
            self.simulator.generator.manual_seed(int(seed))
