"""The compiled kernels, optional: the nozzle joint's RK4, the engine's step, the vector envs'
episode draws and the nozzle family's batch scoring. Without a C compiler the package installs
and runs on their references, which give the same bits (ssme_envs.models.nozzle_joint,
ssme_envs.models.engine_step, numpy's generators in ssme_envs.envs.episode_draws, numpy's batch
step in ssme_envs.envs.nozzle_compiled)."""

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext


class BuildExt(build_ext):
    """Flags per compiler: the kernel's bits rely on no fused multiply-add and no fast math."""

    def build_extensions(self) -> None:
        flags = (
            ["/O2", "/fp:precise"]
            if self.compiler.compiler_type == "msvc"
            else ["-O3", "-ffp-contract=off", "-fno-fast-math", "-fno-trapping-math", "-std=c99"]
        )
        for ext in self.extensions:
            ext.extra_compile_args = flags
        super().build_extensions()


# included by the kernels
HEADERS = (
    "_buffers.h",
    "_clones.h",
    "_joint_arithmetic.h",
    "_engine_arithmetic.h",
    "_draw_streams.h",
    "_draw_wide.h",
)

setup(
    ext_modules=[
        Extension(
            f"ssme_envs.models.{name}",
            [f"src/ssme_envs/models/{name}.c"],
            depends=[f"src/ssme_envs/models/{header}" for header in HEADERS],
            optional=True,
        )
        for name in ("_joint_kernel", "_engine_kernel", "_draw_kernel", "_score_kernel")
    ],
    cmdclass={"build_ext": BuildExt},
)
