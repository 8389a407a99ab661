"""The nozzle joint's compiled RK4 kernel, optional: without a C compiler the package installs
and runs on its Python reference, which gives the same bits (ssme_envs.models.nozzle_joint)."""

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


setup(
    ext_modules=[
        Extension("ssme_envs.models._joint_kernel", ["src/ssme_envs/models/_joint_kernel.c"], optional=True)
    ],
    cmdclass={"build_ext": BuildExt},
)
