"""What the Python benchmarks share (bench/bench_*.py import it from their own folder)."""
import subprocess


def cpu_model():
    """lscpu's model name with its family and model numbers: every figure
    names the CPU it was measured on, and virtual hosts often report a bare
    "AMD EPYC" for different generations (family 25: Zen 3/4, 26: Zen 5)."""
    name, family, model = "unknown CPU", None, None
    try:
        for line in subprocess.run(["lscpu"], capture_output=True, text=True).stdout.splitlines():
            key, _, value = line.partition(":")
            if key == "Model name":
                name = value.strip()
            elif key == "CPU family":
                family = value.strip()
            elif key == "Model":
                model = value.strip()
    except OSError:
        pass
    return f"{name} (family {family}, model {model})" if family and model else name
