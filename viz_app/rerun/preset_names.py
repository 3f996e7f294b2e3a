"""The names of the scenes ``radarviz demo``, ``record`` and ``radarviz.show`` can build.

A module of its own, without Rerun, so that the public API checks a name before it imports
the scenes (``viz_app.rerun.scenes`` builds them).
"""

from __future__ import annotations

PRESETS: tuple[str, ...] = ("demo", "prosov", "prosov3d", "gorshkov", "velocity", "manoeuvre")
