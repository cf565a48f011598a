r"""One function over a batch of members, the batch split across every device JAX sees.

`ShardedMap(fn)` evaluates `vmap(fn)` on a batch whose leading axis is laid out over a
one-axis device mesh (`jax.sharding.Mesh` named `"batch"`) of all devices: the local ones
(GPUs, or CPU devices made with `--xla_force_host_platform_device_count`) and, after
`jax.distributed.initialize()`, those of every process on every host. Each process runs
the same script with the same inputs; JAX places each member on its device and
`multihost_utils.process_allgather` hands every process the whole result.

Two ways to split (the `mode`):

* `"shard_map"` (default): `jax.shard_map` of the `vmap`. Each device runs its own
  members' loops: a member whose continuation or Newton needs more iterations holds up
  only its own device.
* `"sharding"`: `jit` of the `vmap` with `NamedSharding` on its input and output; XLA's
  SPMD partitioner splits the batch. The loop conditions of a batched `while_loop` reduce
  over the whole batch, so every device iterates until the slowest member anywhere is
  done (an all-reduce per iteration).

Both give identical numbers. `benchmarks/bench_sweep.py` measures them side by side
(`benchmarks/results/sweep.md`): on a phase diagram `"shard_map"` over several devices runs
faster than one device, and `"sharding"` slower than one device (its devices wait for the
slowest member anywhere).

A batch holds `size = devices x per_device` members; `__call__` pads a shorter one by
repeating its last member and drops the padding from the result.
"""

from __future__ import annotations

import numpy as np

import jax
from jax.sharding import Mesh, NamedSharding, PartitionSpec as P

MODES = ("shard_map", "sharding")


def process_index() -> int:
    return jax.process_index()


def _global(a, sharding):
    """A global array from `a` (the same NumPy array on every process) laid out by `sharding`."""
    a = np.asarray(a)
    return jax.make_array_from_callback(a.shape, sharding, lambda idx: a[idx])


def _gather(tree):
    """The whole of every (possibly multi-process) array of `tree`, as NumPy, on every process."""
    if jax.process_count() > 1:
        from jax.experimental import multihost_utils

        return jax.tree.map(np.array, multihost_utils.process_allgather(tree, tiled=True))
    return jax.tree.map(np.asarray, jax.device_get(tree))


def agree(tree):
    """`tree` (NumPy arrays) as process 0 has it, on every process (a no-op with one process):
    what to compute is decided once, so that every process runs the same batches."""
    if jax.process_count() == 1:
        return tree
    from jax.experimental import multihost_utils

    return jax.tree.map(np.array, multihost_utils.broadcast_one_to_all(tree))  # writable copies


class ShardedMap:
    r"""`fn(member, shared)` over a batch of members, split across `devices`.

    **Arguments:** `fn` a traceable function of one member (a pytree of arrays without the
    batch axis) and of `shared` (a pytree replicated on every device, or None); `devices`
    the devices to use (default `jax.devices()`: all devices of all processes);
    `per_device` members per device in one call (the `vmap` width on each device); `mode`
    `"shard_map"` or `"sharding"` (module docstring).

    Calling it with `members` (leading axis of any length up to `size`) returns the outputs
    as NumPy arrays with that leading axis, and `device_of`, the id of the device each
    member ran on. One compiled program serves every call with the same shapes.
    """

    def __init__(self, fn, *, devices=None, per_device: int = 1, mode: str = "shard_map"):
        if mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
        if isinstance(per_device, bool) or not isinstance(per_device, (int, np.integer)) or per_device < 1:
            raise ValueError(f"per_device must be a positive integer, got {per_device!r}")
        devices = list(jax.devices() if devices is None else devices)
        if not devices:
            raise ValueError("devices: at least one device is needed")
        self.devices = devices
        self.per_device = int(per_device)
        self.mode = mode
        self.mesh = Mesh(np.asarray(devices, dtype=object), ("batch",))
        self.size = len(devices) * self.per_device
        self._batch = NamedSharding(self.mesh, P("batch"))
        self._replicated = NamedSharding(self.mesh, P())
        batched = jax.vmap(fn, in_axes=(0, None))
        if mode == "shard_map":
            self._fn = jax.jit(jax.shard_map(batched, mesh=self.mesh, in_specs=(P("batch"), P()),
                                             out_specs=P("batch"), check_vma=False))
        else:
            self._fn = jax.jit(batched, in_shardings=(self._batch, self._replicated), out_shardings=self._batch)

    def device_ids(self) -> np.ndarray:
        """The id of the device that runs each of the `size` members of a batch."""
        out = np.empty(self.size, dtype=np.int64)
        for dev, idx in self._batch.devices_indices_map((self.size,)).items():
            out[idx[0]] = dev.id
        return out

    def __call__(self, members, shared=None):
        leaves = jax.tree.leaves(members)
        if not leaves:
            raise ValueError("members: at least one array is needed")
        count = int(np.shape(leaves[0])[0])
        if not 0 < count <= self.size:
            raise ValueError(f"members: a batch holds 1 to {self.size} members, got {count}")
        pad = self.size - count

        def padded(a):
            a = np.asarray(a)
            return np.concatenate([a, np.repeat(a[-1:], pad, axis=0)]) if pad else a

        xs = jax.tree.map(lambda a: _global(padded(a), self._batch), members)
        sh = jax.tree.map(lambda a: _global(a, self._replicated), shared)
        out = _gather(self._fn(xs, sh))
        return jax.tree.map(lambda a: a[:count], out), self.device_ids()[:count]

    def _specs(self, members, shared):
        xs = jax.tree.map(lambda a: jax.ShapeDtypeStruct((self.size,) + np.shape(a)[1:], np.asarray(a).dtype,
                                                          sharding=self._batch), members)
        sh = jax.tree.map(lambda a: jax.ShapeDtypeStruct(np.shape(a), np.asarray(a).dtype,
                                                          sharding=self._replicated), shared)
        return xs, sh

    def output_shapes(self, members, shared=None):
        """Shapes and dtypes of one member's outputs for a batch like `members`. It traces the
        batched program itself, so the call that follows reuses that trace."""
        out = self._fn.eval_shape(*self._specs(members, shared))
        return jax.tree.map(lambda s: jax.ShapeDtypeStruct(s.shape[1:], s.dtype), out)

    def lower(self, members, shared=None):
        """The lowered program for a batch like `members` (compile-time measurements)."""
        return self._fn.lower(*self._specs(members, shared))
