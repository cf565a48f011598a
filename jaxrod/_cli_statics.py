"""Statics subcommands beyond `equilibrium`/`snap-angles`: hysteresis, phase-diagram.

Each module in `jaxrod._cli._COMMAND_MODULES` defines `register(sub)`, which adds its
subparsers to the `jaxrod` parser and attaches `handler=<function(args) -> exit code>`
with `set_defaults`. Shared pieces: `jaxrod._cli.add_scene_args`, `make_scene_from_args`,
`InputError` (one-line error, exit 2), `EXIT_OK`, `EXIT_USAGE`, `EXIT_NOT_CONVERGED`.
"""


def register(sub):
    """Add this module's subcommands to the `jaxrod` argument parser (none yet)."""
