"""The paper's network (Table 3, eq. 1) and the baselines built from the same blocks."""

from __future__ import annotations

import copy

import pytest
import torch
from hydra import compose, initialize_config_dir
from torch import nn

from baselines.coordinate_net import CoordinateDuelingQNet
from baselines.min_net import MinDuelingQNet
from hgm_repro.contracts.conf_dir import CONF_DIR
from hgm_repro.contracts.schema import check_config
from hgm_repro.models.builders import make_network
from hgm_repro.models.networks import (
    DuelingHead,
    TwoStreamDuelingQNet,
    conv_stack,
    dueling_combine,
    param_counts,
)

N_ACTIONS = 5


def images(batch: int, channels: int = 12, side: int = 84, seed: int = 0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return torch.randint(0, 256, (batch, channels, side, side), dtype=torch.uint8, generator=g)


def conv_grads(net: TwoStreamDuelingQNet, camera: torch.Tensor, hgm: torch.Tensor) -> list[torch.Tensor]:
    net.zero_grad()
    net(camera, hgm).sum().backward()
    return [p.grad.clone() for p in net.shared_conv.parameters()]


def test_one_conv_stack_serves_both_streams():
    net = TwoStreamDuelingQNet(N_ACTIONS, 12, (84, 84))
    convs = [m for m in net.modules() if isinstance(m, nn.Conv2d)]
    assert len(convs) == 3, "Table 3 has three conv layers, and both streams must use the same ones"
    one_stack = sum(p.numel() for p in conv_stack(12).parameters())
    assert param_counts(net)["params/shared_conv"] == one_stack


@pytest.mark.parametrize("stream", ["camera", "hgm"])
def test_gradients_reach_the_shared_conv_from_each_stream(stream):
    torch.manual_seed(0)
    net = TwoStreamDuelingQNet(N_ACTIONS, 12, (84, 84))
    features = net.shared_conv.out_features
    # Cut the other stream out of the head: the conv's gradient then flows only through `stream`.
    other = slice(features, None) if stream == "camera" else slice(0, features)
    cut = copy.deepcopy(net)
    with torch.no_grad():
        for head in (cut.head.value, cut.head.advantage):
            head[0].weight[:, other] = 0
    camera, hgm = images(4, seed=1), images(4, seed=2)
    grads = conv_grads(cut, camera, hgm)
    assert all(g.abs().sum() > 0 for g in grads), f"no gradient reaches the conv stack through {stream}"
    # And that stream's input is what drives it: changing the other input leaves it unchanged.
    if stream == "camera":
        again = conv_grads(cut, camera, images(4, seed=3))
    else:
        again = conv_grads(cut, images(4, seed=3), hgm)
    assert all(torch.allclose(a, b, atol=1e-6) for a, b in zip(grads, again, strict=True))


def test_both_streams_change_the_action_values():
    net = TwoStreamDuelingQNet(N_ACTIONS, 12, (84, 84))
    camera, hgm = images(2, seed=1), images(2, seed=2)
    q = net(camera, hgm)
    assert not torch.allclose(q, net(images(2, seed=3), hgm))
    assert not torch.allclose(q, net(camera, images(2, seed=4)))


def test_dueling_combination_is_eq_1():
    torch.manual_seed(0)
    head = DuelingHead(32, N_ACTIONS, [16, 8])
    x = torch.randn(6, 32)
    value, advantage = head.value(x), head.advantage(x)
    q = head(x)
    assert torch.allclose(q, value + advantage - advantage.mean(-1, keepdim=True), atol=1e-6)
    assert torch.allclose(q.mean(-1, keepdim=True), value, atol=1e-6)  # mean advantage is zero
    assert torch.allclose(dueling_combine(torch.zeros(1, 1), torch.tensor([[1.0, 3.0]])), torch.tensor([[-1.0, 1.0]]))


def test_param_counts_match_table_3_at_84x84():
    net = TwoStreamDuelingQNet(N_ACTIONS, 12, (84, 84))
    conv = (12 * 32 * 8 * 8 + 32) + (32 * 64 * 4 * 4 + 64) + (64 * 64 * 3 * 3 + 64)
    features = 2 * 64 * 7 * 7  # 84 -> 20 -> 9 -> 7, two streams concatenated

    def head(out: int) -> int:
        return (features * 512 + 512) + (512 * 256 + 256) + (256 * out + out)

    counts = param_counts(net)
    assert counts["params/shared_conv"] == conv
    assert counts["params/head"] == head(1) + head(N_ACTIONS)
    assert counts["params/total"] == conv + head(1) + head(N_ACTIONS)


def test_inputs_are_decoded_from_uint8():
    net = TwoStreamDuelingQNet(N_ACTIONS, 3, (36, 36))
    seen = {}
    net.shared_conv.register_forward_pre_hook(lambda m, args: seen.setdefault("x", args[0]))
    net(torch.full((1, 3, 36, 36), 255, dtype=torch.uint8), torch.zeros(1, 3, 36, 36, dtype=torch.uint8))
    camera, hgm = seen["x"][0], seen["x"][1]
    assert torch.all(camera == 1.0) and torch.all(hgm == -1.0)  # /255 and x/127.5 - 1


def test_any_leading_batch_shape():
    net = MinDuelingQNet(N_ACTIONS, 6, (36, 36))
    assert net(images(1, 6, 36)[0]).shape == (N_ACTIONS,)
    assert net(images(6, 6, 36).reshape(2, 3, 6, 36, 36)).shape == (2, 3, N_ACTIONS)


def test_coordinate_net_reads_camera_and_v2x_vector():
    net = CoordinateDuelingQNet(N_ACTIONS, 6, (36, 36), coord_dim=2 * 16 * 6)
    assert net.in_keys == ["camera", "coordinates"]
    q = net(images(3, 6, 36), torch.randn(3, 2 * 16 * 6))
    assert q.shape == (3, N_ACTIONS)
    with pytest.raises(ValueError, match="coord_dim"):
        CoordinateDuelingQNet(N_ACTIONS, 6, (36, 36))


@pytest.mark.parametrize("model, keys", [("proposed", ["camera", "hgm"]), ("min", ["camera"]),
                                         ("coordinate", ["camera", "coordinates"])])
def test_every_model_config_builds_its_network(model, keys):
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        job = check_config(compose("config", overrides=[f"model={model}", "observation.height=36",
                                                        "observation.width=36"]))
    net = make_network(job)
    assert net.in_keys == keys
    assert set(keys) <= {k for k, v in job.model.streams.items() if v not in ("none", False)} | {"coordinates"}
    counts = param_counts(net)
    assert counts["params/total"] == sum(v for k, v in counts.items() if k != "params/total")


def test_table3_is_written_once_and_every_learned_model_uses_it():
    """Table 3's conv stack lives in conf/model/network/table3.yaml only: the model configs include it
    and the code's defaults (`PAPER_CONV`, `PAPER_HIDDEN`, the smallest image) are read from it."""
    from pathlib import Path

    from hgm_repro.contracts.table3 import MIN_IMAGE_SIDE, PAPER_CONV, PAPER_HIDDEN

    repo = Path(CONF_DIR).parent
    written = sorted(str(p.relative_to(repo)) for folder in ("conf", "hgm_repro", "baselines")
                     for p in (repo / folder).rglob("*") if p.suffix in (".yaml", ".py")
                     and "[32, 8, 4]" in p.read_text())
    assert written == ["conf/model/network/table3.yaml"]
    assert PAPER_CONV == [[32, 8, 4], [64, 4, 2], [64, 3, 1]] and PAPER_HIDDEN == [512, 256]
    assert MIN_IMAGE_SIDE == 36  # 36 -> 8 -> 3 -> 1
    with initialize_config_dir(str(CONF_DIR), version_base="1.3"):
        for model in ("proposed", "min", "coordinate"):
            network = compose("config", overrides=[f"model={model}"]).model.network
            assert [list(layer) for layer in network.conv] == PAPER_CONV and list(network.hidden) == PAPER_HIDDEN
