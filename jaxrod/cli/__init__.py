"""The `jaxrod` command line: statics, dynamics, design and `jaxrod reproduce`.

The top layer: it may import anything below it, the design package included.
"""

from ._main import main as main
