// brume — backend names (compiled with or without the GPU backend).
#include "brume/error.hpp"
#include "brume/exec.hpp"
#include "brume/gpu_context.hpp"

namespace brume {

const EnumNames<Backend>& backend_names() {
  static const EnumNames<Backend> n = {{Backend::cpu, "cpu"}, {Backend::gpu, "gpu"}, {Backend::automatic, "auto"}};
  return n;
}
const EnumNames<GpuFilter>& gpu_filter_names() {
  static const EnumNames<GpuFilter> n = {
      {GpuFilter::automatic, "auto"}, {GpuFilter::hardware, "hardware"}, {GpuFilter::shader, "shader"}};
  return n;
}


// Names come from the one name table of each enum (brume/pipeline.hpp).
std::string to_string(Backend b) { return enum_name(backend_names(), b); }
std::string to_string(GpuFilter f) { return enum_name(gpu_filter_names(), f); }

void gpu_unavailable() {
  throw GpuUnavailable("no OpenGL ES 3.2 context: this brume was built without the GPU backend (EGL/GLES 3.2 headers were "
                       "missing at build time: apt libegl-dev libgles-dev); use --backend cpu");
}

}  // namespace brume
