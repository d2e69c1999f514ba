"""benchmarks"""

from posedrift.benchmarks._cpd import markdown_table, run_cpd_benchmark
from posedrift.benchmarks._render import RenderBenchmark, bench_render
from posedrift.benchmarks._track import TrackBenchmark, bench_track, render_sequences

__all__: list[str] = []
__all__ += ["markdown_table", "run_cpd_benchmark"]
__all__ += ["RenderBenchmark", "bench_render"]
__all__ += ["TrackBenchmark", "bench_track", "render_sequences"]
