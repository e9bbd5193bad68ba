"""A learned field prior: how likely each part of the area is to be interesting, from a local map.

The belief maps treat cells as independent, and the Gaussian smoothing of
:mod:`ipp_toolkit.belief.interest` (``ig_spatial``'s prior) only says "near what was seen
interesting". Real fields have shapes: a straight boundary continues, hotspots have typical
sizes, textures repeat. A small convolutional network that has seen many ground truths
predicts

    pi(block) = P(a cell of the block is interesting | the UAV's local map)

for every block of about :data:`BLOCK_METRES` metres, from what the UAV itself knows (its
local map, which holds its own readings and those it heard). It is trained by supervised
learning on simulator ground truth (``ipp-train prior``, :mod:`baselines.field_prior.training`);
this module owns only what inference needs: the input planes, the network, the file format
and the prediction, so a planner that flies a prior never imports the trainer.

Input planes, per block of about 2 m (:func:`block_cells`; the map is padded to whole
blocks, and a partial block averages over its part inside the area), taken over squares of
about 0.5 m (the cells themselves at r_M >= 0.5 m):

- ``prob``: mean probability minus 0.5;
- ``certainty``: mean of ``|2 p - 1|`` (how much is known);
- ``interesting`` / ``uninteresting``: the share of squares with p > 0.6 / p < 0.4 (read at
  least once, either way);
- ``inside``: the share of the block inside the area (0 for padding).

Output: (N, h, w) probabilities per block, calibrated (trained with cross-entropy against the
share of interesting cells of each block). :meth:`FieldPrior.fine_values` resamples them
bilinearly onto a finer block grid (e.g. the 0.5 m blocks ``ig_spatial`` evaluates on).

Cost: one forward pass per decision for the whole team (N maps batched); 6-9 ms for four
UAVs on one CPU thread (experiments/field-prior/README.md, "Cost"). torch is imported on first use.
"""

from __future__ import annotations

import functools
import os
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..config.schema import GAIN_INTEREST_LEARNED
from ..io import CheckpointError, load_torch, save_torch
from .interest import block_means, block_sums, square_cells

__all__ = ["BLOCK_METRES", "FORMAT", "INPUT_PLANES", "SHIPPED_PRIOR", "FieldPrior",
           "PriorNetConfig", "block_average", "block_cells", "block_labels", "build_network",
           "parameter_count", "prior_file", "prior_inputs", "resample_matrix", "shared_prior",
           "square_inputs"]

#: Side of the blocks the prior sees and predicts, in metres.
BLOCK_METRES = 2.0
#: The input planes, in order.
INPUT_PLANES = ("prob", "certainty", "interesting", "uninteresting", "inside")
#: The format tag of a field-prior file (:func:`ipp_toolkit.io.load_torch`).
FORMAT = "ipp-toolkit/field-prior"
#: Largest network a file may ask for (channels of the first level); the default is 8.
MAX_WIDTH = 128
#: The packaged prior (``ipp-train prior --seed 0``; its JSON record beside it): the one
#: ``ig_learned`` flies and ``features.gain_interest = "learned"`` reads.
SHIPPED_PRIOR = Path(__file__).resolve().parents[1] / "data" / "field_prior.pt"
#: The name that stands for :data:`SHIPPED_PRIOR` in configs and on command lines.
SHIPPED_NAME = GAIN_INTEREST_LEARNED


def _sub_block(resolution: float, size: int) -> int:
    """Cells per side of the ~0.5 m squares the maps are averaged over first (divides
    ``size``; 1 at r_M >= 0.5 m): the squares of :mod:`ipp_toolkit.belief.interest`."""
    return square_cells(size, resolution)


def block_cells(resolution: float, size: int) -> int:
    """Cells per block side at map resolution ``resolution`` metres for maps of ``size``
    cells per side: a whole number of ~0.5 m squares, about :data:`BLOCK_METRES` in all."""
    sub = _sub_block(resolution, size)
    return sub * max(1, int(round(BLOCK_METRES / (sub * resolution))))


def _block_sums(values: np.ndarray, b: int) -> np.ndarray:
    """(N, h, w) float32 sums over b x b blocks of (N, H, W) ``values``, zero-padded."""
    n, rows, cols = values.shape
    h, w = -(-rows // b), -(-cols // b)
    if (h * b, w * b) != (rows, cols):
        padded = np.zeros((n, h * b, w * b), dtype=np.float32)
        padded[:, :rows, :cols] = values
        values = padded
    return block_sums(np.ascontiguousarray(values), b)


@functools.lru_cache(maxsize=16)
def _inside_share(rows: int, cols: int, b: int) -> np.ndarray:
    """(h, w) float32 share of each b x b block's cells inside a rows x cols area (read-only,
    kept per shape: every planning step asks for the same one)."""
    share = _block_sums(np.ones((1, rows, cols), dtype=np.float32), b)[0] / np.float32(b * b)
    share.flags.writeable = False
    return share


def _inside_count(inside: np.ndarray, b: int) -> np.ndarray:
    """Cells of each block inside the area (at least 1, so padding blocks average to 0)."""
    return np.maximum(inside * np.float32(b * b), np.float32(1.0))


def block_average(values: np.ndarray, b: int) -> np.ndarray:
    """(N, h, w) float32 mean of (N, H, W) ``values`` over the cells of every b x b block
    that lie inside the area (the map padded to whole blocks; a padding block is 0)."""
    count = _inside_count(_inside_share(*values.shape[1:], b), b)
    return _block_sums(values, b) / count


def prior_inputs(prob: np.ndarray, resolution: float) -> np.ndarray:
    """The (N, 5, h, w) float32 input planes (:data:`INPUT_PLANES`) of (N, H, W) local maps.

    The maps are first averaged over squares of about 0.5 m (:func:`~ipp_toolkit.belief.
    interest.block_means`; the cells themselves at r_M >= 0.5 m), so the planes mean the same
    at every resolution and cost little at fine ones: certainty and the two shares are
    taken over those squares.

    Args:
        prob: (N, H, W) float32 probabilities of interest of N local maps (H = W).
        resolution: the maps' cell side r_M in metres.
    """
    prob = np.ascontiguousarray(prob, dtype=np.float32)
    if prob.ndim != 3 or prob.shape[1] != prob.shape[2]:
        raise ValueError(f"expected (N, H, H) probability maps, got shape {prob.shape}")
    sub = _sub_block(resolution, prob.shape[1])
    squares = block_means(prob, sub) if sub > 1 else prob
    return square_inputs(squares, resolution, prob.shape[1])


def square_inputs(squares: np.ndarray, resolution: float, size: int) -> np.ndarray:
    """:func:`prior_inputs` from the maps' ~0.5 m square means (N, H / s, W / s), s =
    :func:`~ipp_toolkit.belief.interest.square_cells` (e.g. kept up to date by
    :class:`~ipp_toolkit.belief.interest.BlockMeanCache`); ``size`` = H = W."""
    squares = np.ascontiguousarray(squares, dtype=np.float32)
    b = block_cells(resolution, size) // _sub_block(resolution, size)
    n, rows, cols = squares.shape
    inside = _inside_share(rows, cols, b)
    count = _inside_count(inside, b)
    planes = np.empty((n, len(INPUT_PLANES)) + inside.shape, dtype=np.float32)
    planes[:, 0] = _block_sums(squares - np.float32(0.5), b) / count
    planes[:, 1] = _block_sums(np.abs(squares * np.float32(2.0) - np.float32(1.0)), b) / count
    planes[:, 2] = _block_sums((squares > 0.6).astype(np.float32), b) / count
    planes[:, 3] = _block_sums((squares < 0.4).astype(np.float32), b) / count
    planes[:, 4] = inside
    return planes


def block_labels(ground_truth: np.ndarray, resolution: float) -> np.ndarray:
    """(h, w) float32 share of interesting cells of every block of an (H, W) ground truth
    (the training target; padding blocks are 0)."""
    truth = np.asarray(ground_truth, dtype=np.float32)[None]
    return block_average(truth, block_cells(resolution, truth.shape[1]))[0]


@functools.lru_cache(maxsize=32)
def resample_matrix(n_fine: int, fine_cells: int, n_coarse: int, coarse_cells: int
                    ) -> np.ndarray:
    """(n_fine, n_coarse) float32 bilinear weights from coarse blocks to fine blocks.

    Block i of side ``fine_cells`` cells has its centre at ``(i + 0.5) * fine_cells``; it
    takes the linear interpolation of the two coarse blocks whose centres surround it (the
    nearest one at the border). ``A @ coarse @ A.T`` resamples a (n_coarse, n_coarse) grid.
    """
    centre = (np.arange(n_fine) + 0.5) * fine_cells / coarse_cells - 0.5
    centre = np.clip(centre, 0.0, n_coarse - 1)
    low = np.floor(centre).astype(np.intp)
    high = np.minimum(low + 1, n_coarse - 1)
    frac = centre - low
    weights = np.zeros((n_fine, n_coarse), dtype=np.float64)
    weights[np.arange(n_fine), low] += 1.0 - frac
    weights[np.arange(n_fine), high] += frac
    return weights.astype(np.float32)


@dataclass(frozen=True)
class PriorNetConfig:
    """The network's sizes.

    Attributes:
        width: channels of the first level (the second and the bottleneck have twice as many).
    """

    width: int = 8

    def __post_init__(self) -> None:
        if (isinstance(self.width, bool) or not isinstance(self.width, int)
                or not 1 <= self.width <= MAX_WIDTH):
            raise ValueError(f"width must be an integer in [1, {MAX_WIDTH}], got {self.width!r}")


def build_network(config: PriorNetConfig) -> Any:
    """A fresh :class:`torch.nn.Module` mapping (B, 5, h, w) planes to (B, h, w) logits.

    A two-level U-Net (3 x 3 convolutions, average pooling, bilinear upsampling, skip
    connections) whose bottleneck also sees the mean of its features over the area, so the
    whole map (one straight boundary or many hotspots) informs every block.
    """
    import torch
    from torch import nn
    from torch.nn import functional as F

    def pair(c_in: int, c_out: int) -> nn.Sequential:
        return nn.Sequential(nn.Conv2d(c_in, c_out, 3, padding=1), nn.ReLU(),
                             nn.Conv2d(c_out, c_out, 3, padding=1), nn.ReLU())

    def run_pair(layers: nn.Sequential, x: torch.Tensor) -> torch.Tensor:
        # The layers' own operations, called directly: a prediction inside a planning step
        # is a few small convolutions, where the modules' call machinery costs a seventh.
        first, second = layers[0], layers[2]
        x = torch.relu(torch.conv2d(x, first.weight, first.bias, 1, 1))
        return torch.relu(torch.conv2d(x, second.weight, second.bias, 1, 1))

    class FieldPriorNet(nn.Module):
        def __init__(self, width: int) -> None:
            super().__init__()
            c1, c2 = width, 2 * width
            self.enc1 = pair(len(INPUT_PLANES), c1)
            self.enc2 = pair(c1, c2)
            self.mid = pair(2 * c2, c2)
            self.dec2 = pair(2 * c2, c2)
            self.dec1 = pair(c2 + c1, c1)
            self.head = nn.Conv2d(c1, 1, 1)

        def forward(self, planes: torch.Tensor) -> torch.Tensor:
            h, w = planes.shape[-2:]
            ph, pw = -h % 4, -w % 4  # two halvings
            x = F.pad(planes, (0, pw, 0, ph))
            e1 = run_pair(self.enc1, x)
            e2 = run_pair(self.enc2, F.avg_pool2d(e1, 2))
            low = F.avg_pool2d(e2, 2)
            context = low.mean(dim=(2, 3), keepdim=True).expand_as(low)
            m = run_pair(self.mid, torch.cat([low, context], dim=1))
            d2 = run_pair(self.dec2, torch.cat([F.interpolate(
                m, scale_factor=2.0, mode="bilinear", align_corners=False), e2], dim=1))
            d1 = run_pair(self.dec1, torch.cat([F.interpolate(
                d2, scale_factor=2.0, mode="bilinear", align_corners=False), e1], dim=1))
            return torch.conv2d(d1, self.head.weight, self.head.bias)[:, 0, :h, :w]

    return FieldPriorNet(config.width)


class FieldPrior:
    """A trained field prior, ready to predict (inference only: no gradients, one thread).

    Args:
        network: the module from :func:`build_network`, weights loaded.
        config: its sizes.
        record: what the file says of how it was trained (JSON-safe; may be empty).
    """

    def __init__(self, network: Any, config: PriorNetConfig,
                 record: dict[str, Any] | None = None) -> None:
        self.network = network.eval()
        self.config = config
        self.record = dict(record or {})
        # The last square_values call: (resolution, size, squares, result). The gain planes
        # and a planner's teammate discount ask for the same team's squares in one step.
        self._last_squares: tuple[float, int, np.ndarray, np.ndarray] | None = None
        self._channels_last = False

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> FieldPrior:
        """Load a file written by :meth:`save`.

        Raises:
            CheckpointError: missing, corrupt, foreign, non-finite, or weights that do not
                fit the network the file describes.
        """
        data = load_torch(path, FORMAT)
        try:
            config = PriorNetConfig(**dict(data["network"]))
            record = dict(data.get("record", {}))
            state = data["state_dict"]
        except (KeyError, TypeError, ValueError) as error:
            raise CheckpointError(f"field prior {str(path)!r} is malformed: {error}") from None
        network = build_network(config)
        try:
            network.load_state_dict(state)
        except (RuntimeError, TypeError, AttributeError) as error:
            first = (str(error).splitlines() or [""])[0][:200]
            raise CheckpointError(f"field prior {str(path)!r} does not fit its network "
                                  f"(width {config.width}): {first}") from None
        return cls(network, config, record)

    def save(self, path: str | os.PathLike[str]) -> None:
        """Atomically write the weights, sizes and record (plain data only)."""
        save_torch(path, {"network": asdict(self.config), "record": self.record,
                          "state_dict": self.network.state_dict()}, FORMAT)

    def predict(self, prob: np.ndarray, resolution: float) -> np.ndarray:
        """(N, h, w) float32 probability of interest of every block of N local maps.

        Args:
            prob: (N, H, W) float32 probabilities of the local maps.
            resolution: their cell side r_M in metres.
        """
        return self._forward(prior_inputs(prob, resolution))

    def _forward(self, planes: np.ndarray) -> np.ndarray:
        import torch

        with torch.inference_mode():
            inputs = torch.from_numpy(planes)
            if self._channels_last:
                inputs = inputs.contiguous(memory_format=torch.channels_last)
            return torch.sigmoid(self.network(inputs)).numpy()

    def for_planning(self) -> FieldPrior:
        """This prior with its weights in channels-last order, for the predictions of
        planning steps: a few small convolutions of a handful of maps each, which take
        about half the time in that order on one CPU thread. The predictions differ from
        the default order's in the last bits of float32 (about 1e-6). Changes this object
        (the network is converted in place); returns it."""
        import torch

        self.network = self.network.to(memory_format=torch.channels_last)
        self._channels_last = True
        return self

    def fine_values(self, prob: np.ndarray, resolution: float, fine_cells: int) -> np.ndarray:
        """(N, H / f, W / f) float32 prior on blocks of ``fine_cells`` = f cells per side.

        The predicted 2 m blocks resampled bilinearly (:func:`resample_matrix`); ``H`` and
        ``W`` must be multiples of ``f``.
        """
        rows, cols = prob.shape[-2:]
        if rows % fine_cells or cols % fine_cells:
            raise ValueError(f"maps of {rows} x {cols} cells do not divide into blocks of "
                             f"{fine_cells}")
        return self._resampled(self.predict(prob, resolution), resolution, rows, fine_cells)

    def square_values(self, squares: np.ndarray, resolution: float, size: int) -> np.ndarray:
        """(N, H / s, W / s) float32 prior on the maps' ~0.5 m squares, from their means
        (:func:`square_inputs`): :meth:`fine_values` with ``fine_cells`` = s, without the
        maps' cells (``size`` = H = W). Asked again for the same squares (the last call's,
        compared value by value), it returns a copy of that answer without a second forward
        pass."""
        last = self._last_squares
        if (last is not None and last[0] == resolution and last[1] == size
                and last[2].shape == squares.shape and np.array_equal(last[2], squares)):
            return last[3].copy()
        coarse = self._forward(square_inputs(squares, resolution, size))
        result = self._resampled(coarse, resolution, size, _sub_block(resolution, size))
        self._last_squares = (resolution, size, np.array(squares, copy=True), result)
        return result.copy()

    @staticmethod
    def _resampled(coarse: np.ndarray, resolution: float, size: int,
                   fine_cells: int) -> np.ndarray:
        b = block_cells(resolution, size)
        left = resample_matrix(size // fine_cells, fine_cells, coarse.shape[1], b)
        right = resample_matrix(size // fine_cells, fine_cells, coarse.shape[2], b)
        return left @ coarse @ right.T


def parameter_count(config: PriorNetConfig) -> int:
    """Number of weights of the network of ``config`` (without building it)."""
    c1, c2, planes = config.width, 2 * config.width, len(INPUT_PLANES)

    def pair(c_in: int, c_out: int) -> int:
        return c_in * c_out * 9 + c_out + c_out * c_out * 9 + c_out

    return (pair(planes, c1) + pair(c1, c2) + pair(2 * c2, c2) + pair(2 * c2, c2)
            + pair(c2 + c1, c1) + c1 + 1)



def prior_file(name: str | os.PathLike[str]) -> Path:
    """The file a prior is named by: :data:`SHIPPED_NAME` (``learned``) for the packaged one,
    else a path to a file written by ``ipp-train prior`` (``RUN/best.pt``).

    Raises:
        CheckpointError: the file does not exist, or the name is a folder.
    """
    path = SHIPPED_PRIOR if str(name) == SHIPPED_NAME else Path(name)
    if path.is_dir():
        raise CheckpointError(f"field prior {str(path)!r} is a folder; give the file "
                              f"(e.g. {str(path / 'best.pt')!r})")
    if not path.is_file():
        hint = ("the package is incomplete; reinstall it" if path == SHIPPED_PRIOR else
                "train one with `ipp-train prior --out RUN` and name RUN/best.pt")
        raise CheckpointError(f"field prior {str(path)!r} does not exist; {hint}")
    return path


def shared_prior(name: str | os.PathLike[str]) -> FieldPrior:
    """The prior named ``name`` (see :func:`prior_file`), loaded once per process and file
    version: every mission that reads it shares one network (inference only, so sharing is
    safe). A file replaced on disk is read again."""
    path = prior_file(name).resolve()
    stat = path.stat()
    return _load_once(str(path), stat.st_mtime_ns, stat.st_size)


@functools.lru_cache(maxsize=8)
def _load_once(path: str, mtime_ns: int, size: int) -> FieldPrior:
    # mtime and size are part of the key so a retrained file is not served stale.
    return FieldPrior.load(path).for_planning()
