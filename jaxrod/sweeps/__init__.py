"""Sweeps across devices, processes and hosts on JAX's own distribution.

`ShardedMap`: one function over a batch of members, the batch laid out over every device
JAX sees (`jax.sharding` / `jax.shard_map`; with `jax.distributed.initialize()`, every
device of every process). `sweep`: a resumable run of a function over a list or grid of
points, stored in NetCDF batch files with its provenance. The phase diagram
(`phase_diagram(batch="shard")`), the speed plane (`speed_plane`) and multi-start design
(`optimize(devices=...)`) run on it.

Layer: infrastructure beside linalg (it imports nothing of the solver).
"""

from ._map import agree as agree
from ._map import MODES as MODES
from ._map import ShardedMap as ShardedMap
from ._sweep import grid as grid
from ._sweep import sweep as sweep
