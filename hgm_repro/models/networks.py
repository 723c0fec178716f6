"""The paper's Q-network (Network Architecture, Table 3) and the building blocks its baselines reuse.

`TwoStreamDuelingQNet` sends the front-camera stack and the Hyper-Grid Matrix stack through one
conv stack (one set of weights for both streams), concatenates the two feature vectors and
feeds them to a dueling head (eq. 1). Min's network (`baselines.min_net`) and the Coordinate
network (`baselines.coordinate_net`) are assembled from the same blocks, so that the three
methods differ only in what they see.

Every network takes uint8 images as the observation builders store them and decodes them
itself: the replay buffer then holds bytes, not floats (four times smaller).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

from ..contracts.table3 import PAPER_CONV, PAPER_HIDDEN  # Table 3 (conf/model/network/table3.yaml)
from ..observations import decode_hgm  # x / 127.5 - 1: the inverse of the builders' encoding


def decode_camera(x: torch.Tensor) -> torch.Tensor:
    """uint8 RGB in [0, 255] -> float in [0, 1]."""
    return x.float() / 255.0


def conv_stack(in_channels: int, conv: Sequence[Sequence[int]] = PAPER_CONV) -> nn.Sequential:
    """Conv + ReLU layers as in Table 3 (no padding), flattened at the end."""
    layers: list[nn.Module] = []
    channels = in_channels
    for filters, kernel, stride in conv:
        layers += [nn.Conv2d(channels, int(filters), int(kernel), int(stride)), nn.ReLU()]
        channels = int(filters)
    layers.append(nn.Flatten())
    return nn.Sequential(*layers)


def conv_output_size(stack: nn.Module, in_channels: int, image_size: Sequence[int]) -> int:
    """Features a conv stack yields for one image, found by a dummy forward.

    Computed once at construction instead of using lazy layers, so `deepcopy` (the target
    network) and `state_dict` work before the first real batch.
    """
    height, width = (int(s) for s in image_size)
    with torch.no_grad():
        out = stack(torch.zeros(1, in_channels, height, width))
    if out.shape[-1] == 0:
        raise ValueError(f"image size {height}x{width} is too small for the conv stack")
    return int(out.shape[-1])


def mlp(in_features: int, hidden: Sequence[int], out_features: int | None = None) -> nn.Sequential:
    """Dense + ReLU layers, then an optional linear output layer."""
    layers: list[nn.Module] = []
    width = in_features
    for h in hidden:
        layers += [nn.Linear(width, int(h)), nn.ReLU()]
        width = int(h)
    if out_features is not None:
        layers.append(nn.Linear(width, out_features))
    return nn.Sequential(*layers)


class DuelingHead(nn.Module):
    """Separate value and advantage streams (Table 3: 512 ReLU, 256 ReLU each), combined by eq. 1.

    Q(s, a) = V(s) + A(s, a) - mean_a' A(s, a'): subtracting the mean makes V and A identifiable.
    """

    def __init__(self, in_features: int, n_actions: int, hidden: Sequence[int] = PAPER_HIDDEN):
        super().__init__()
        self.value = mlp(in_features, hidden, 1)
        self.advantage = mlp(in_features, hidden, n_actions)

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        value = self.value(features)
        advantage = self.advantage(features)
        return dueling_combine(value, advantage)


def dueling_combine(value: torch.Tensor, advantage: torch.Tensor) -> torch.Tensor:
    """Eq. 1: V + A - mean(A) over actions."""
    return value + advantage - advantage.mean(dim=-1, keepdim=True)


class ImageEncoder(nn.Module):
    """A conv stack applied to image batches with any leading batch shape.

    TorchRL calls the network on [N, C, H, W] while collecting, on [B, C, H, W] in the loss,
    and sometimes on unbatched [C, H, W] when checking specs; flattening the leading dims
    lets one module serve them all.
    """

    def __init__(self, in_channels: int, image_size: Sequence[int], conv: Sequence[Sequence[int]] = PAPER_CONV):
        super().__init__()
        self.in_channels = in_channels
        self.layers = conv_stack(in_channels, conv)
        self.out_features = conv_output_size(self.layers, in_channels, image_size)

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        lead = images.shape[:-3]
        flat = images.reshape(-1, *images.shape[-3:])
        return self.layers(flat).reshape(*lead, self.out_features)


class TwoStreamDuelingQNet(nn.Module):
    """The proposed network: camera and HGM through ONE shared conv stack, then a dueling head."""

    in_keys = ["camera", "hgm"]

    def __init__(self, n_actions: int, in_channels: int, image_size: Sequence[int],
                 coord_dim: int | None = None, conv: Sequence[Sequence[int]] = PAPER_CONV,
                 hidden: Sequence[int] = PAPER_HIDDEN, **unused: object):
        super().__init__()
        del coord_dim, unused  # same constructor as the baselines; this network reads no V2X vector
        self.shared_conv = ImageEncoder(in_channels, image_size, conv)
        self.head = DuelingHead(2 * self.shared_conv.out_features, n_actions, hidden)

    def forward(self, camera: torch.Tensor, hgm: torch.Tensor) -> torch.Tensor:
        # One pass over both streams stacked along a new leading dim: the same weights see
        # both images, and the conv runs once on a doubled batch instead of twice.
        images = torch.stack([decode_camera(camera), decode_hgm(hgm)])
        features = self.shared_conv(images)
        return self.head(torch.cat([features[0], features[1]], dim=-1))


def param_counts(net: nn.Module) -> dict[str, int]:
    """Trainable parameters per top-level part of a network, and in total, for the tracker.

    Shared weights count once (the shared conv stack is one module used twice).
    """
    counts = {f"params/{name}": sum(p.numel() for p in child.parameters())
              for name, child in net.named_children()}
    counts["params/total"] = sum(p.numel() for p in net.parameters())
    return counts
