"""The world's errors, in a module of their own so that the runner can catch them without importing pybullet."""


class WorldBuildError(RuntimeError):
    """A world that cannot be built, or an episode that fails in a world built from a non-default config (a config
    the scene does not admit); the message is one line, and the runner ends on it (exit 1, its last checkpoint kept)."""
