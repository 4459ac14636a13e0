// brume — backend names (compiled with or without the GPU backend).
#include "brume/error.hpp"
#include "brume/gpu.hpp"

namespace brume {

Backend parse_backend(const std::string& s) {
  if (s == "cpu") return Backend::cpu;
  if (s == "gpu") return Backend::gpu;
  if (s == "auto") return Backend::automatic;
  throw Error("--backend '" + s + "' is not a backend; use cpu, gpu or auto");
}

std::string to_string(Backend b) { return b == Backend::gpu ? "gpu" : b == Backend::automatic ? "auto" : "cpu"; }

}  // namespace brume
