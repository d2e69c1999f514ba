"""Build the optional compiled CPD kernels (``posedrift.registration._cestep``).

Metadata lives in ``pyproject.toml``; this file only declares the C extension (the
fused E-step in float64 and float32, and the low-rank M-step). It uses the plain buffer
protocol (no NumPy C API), so NumPy is not a build requirement. The extension is
optional: when it cannot be compiled the install still succeeds and posedrift falls
back to its NumPy twins.
"""

from setuptools import Extension, setup

setup(
    ext_modules=[
        Extension(
            "posedrift.registration._cestep",
            sources=["src/posedrift/registration/_cestep.c"],
            extra_compile_args=[
                "-O3",
                "-fno-math-errno",
                "-fopenmp-simd",
                "-ffinite-math-only",
                "-fno-signed-zeros",
                "-fno-trapping-math",
            ],
            optional=True,
        )
    ]
)
