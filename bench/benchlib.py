"""What the Python benchmarks share (bench/bench_*.py import it from their own folder)."""
import subprocess


def cpu_model():
    """lscpu's model name: every figure names the CPU it was measured on."""
    try:
        for line in subprocess.run(["lscpu"], capture_output=True, text=True).stdout.splitlines():
            if line.startswith("Model name:"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return "unknown CPU"
