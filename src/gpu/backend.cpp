// brume — backend names (compiled with or without the GPU backend).
#include "brume/error.hpp"
#include "brume/exec.hpp"

namespace brume {

Backend parse_backend(const std::string& s) {
  if (s == "cpu") return Backend::cpu;
  if (s == "gpu") return Backend::gpu;
  if (s == "auto") return Backend::automatic;
  throw Error("--backend '" + s + "' is not a backend; use cpu, gpu or auto");
}

std::string to_string(Backend b) { return b == Backend::gpu ? "gpu" : b == Backend::automatic ? "auto" : "cpu"; }

GpuFilter parse_gpu_filter(const std::string& s) {
  if (s == "auto") return GpuFilter::automatic;
  if (s == "hardware") return GpuFilter::hardware;
  if (s == "shader") return GpuFilter::shader;
  throw Error("--gpu-filter '" + s + "' is not a filter mode; use auto, hardware or shader");
}

std::string to_string(GpuFilter f) {
  return f == GpuFilter::hardware ? "hardware" : f == GpuFilter::shader ? "shader" : "auto";
}

}  // namespace brume
