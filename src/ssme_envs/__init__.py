"""ssme-envs: identified SSME and movable-nozzle models, and Gymnasium environments on them."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("ssme-envs")
except PackageNotFoundError:  # running from a source tree that was not installed
    __version__ = "0.0.0"


def _register() -> None:
    from ssme_envs.envs.catalogue import register_all

    register_all()


_register()

__all__ = ["__version__"]
