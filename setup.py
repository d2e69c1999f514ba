"""Build the optional compiled kernels (``posedrift.registration._cestep``,
``posedrift.labelling._ckernels``, ``posedrift.skeleton._cmeanshift``,
``posedrift.points._cpoints``).

Metadata lives in ``pyproject.toml``; this file only declares the C extensions (CPD's
fused E-step in float64 and float32, its low-rank M-step, its EM loop and its label transfer;
relabelling's k-NN graph and Dijkstra, the forest's per-point descent and its joint votes'
casting, the part nets' feature matrix; the grouped mean shift of the part modes and the
votes; the segmentation's connected components and the downsampling's voxel centroids).
They use the plain buffer protocol (no NumPy C API), so NumPy is not a build requirement.
Each is optional: when one cannot be compiled the install still succeeds and posedrift
falls back to its NumPy twins.
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
        ),
        # Relabelling's k-NN graph and Dijkstra, the forest's descent. Plain -O3: the
        # code relies on infinities, which -ffinite-math-only would break.
        Extension(
            "posedrift.labelling._ckernels",
            sources=["src/posedrift/labelling/_ckernels.c"],
            extra_compile_args=["-O3"],
            optional=True,
        ),
        # The segmentation's components and the voxel centroids. Plain -O3: float32 compared
        # and doubles summed as NumPy does.
        Extension(
            "posedrift.points._cpoints",
            sources=["src/posedrift/points/_cpoints.c"],
            extra_compile_args=["-O3"],
            optional=True,
        ),
        # Mean shift of the part modes and the joint votes. Plain -O3 (see above).
        Extension(
            "posedrift.skeleton._cmeanshift",
            sources=["src/posedrift/skeleton/_cmeanshift.c"],
            extra_compile_args=["-O3"],
            optional=True,
        ),
    ]
)
