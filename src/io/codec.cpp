// Finding and loading brume_codec.so (see codec.hpp for the search order).
#include "io/codec.hpp"

#include <dlfcn.h>

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <mutex>
#include <string>
#include <vector>

#include "brume/error.hpp"
#include "brume/pipeline.hpp"

#ifndef BRUME_CODEC_BUILD_PATH
#define BRUME_CODEC_BUILD_PATH ""
#endif
#ifndef BRUME_CODEC_INSTALL_PATH
#define BRUME_CODEC_INSTALL_PATH ""
#endif

namespace brume::codec {
namespace {
namespace fs = std::filesystem;

constexpr const char* kModuleName = "brume_codec.so";

std::mutex g_mutex;
std::atomic<const Api*> g_api{nullptr};

// The file that holds this code: the executable, or the shared object
// (the Python extension) libbrume was linked into.
fs::path holder_path() {
  Dl_info info{};
  if (dladdr(reinterpret_cast<void*>(&holder_path), &info) && info.dli_fname && *info.dli_fname) {
    std::error_code ec;
    fs::path p = fs::canonical(info.dli_fname, ec);
    if (!ec) return p;
  }
  std::error_code ec;
  fs::path p = fs::canonical("/proc/self/exe", ec);
  return ec ? fs::path() : p;
}

std::vector<std::string> module_candidates() {
  std::vector<std::string> c;
  // Set, it is the only place looked: a wrong path is an error, not a
  // silent fall-back to some other build's module.
  if (const char* env = std::getenv("BRUME_CODEC_MODULE"); env && *env) return {env};
  const fs::path holder = holder_path();
  if (!holder.empty()) {
    const fs::path dir = holder.parent_path();
    c.push_back((dir / kModuleName).string());
    c.push_back((dir.parent_path() / "lib" / "brume" / kModuleName).string());
  }
  for (const char* p : {BRUME_CODEC_INSTALL_PATH, BRUME_CODEC_BUILD_PATH})
    if (*p) c.emplace_back(p);
  return c;
}

const Api* try_load(const std::string& path, std::string& why) {
  std::error_code ec;
  if (!fs::exists(path, ec)) {
    why = "no such file";
    return nullptr;
  }
  // RTLD_LOCAL: OpenImageIO's 260 libraries stay out of the global scope.
  void* h = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
  if (!h) {
    const char* e = dlerror();
    why = e ? e : "dlopen failed";
    return nullptr;
  }
  using Entry = const Api* (*)();
  auto entry = reinterpret_cast<Entry>(dlsym(h, kEntrySymbol));
  const Api* a = entry ? entry() : nullptr;
  if (!a) {
    why = std::string("no ") + kEntrySymbol + " in it";
    dlclose(h);
    return nullptr;
  }
  if (std::string(a->tag) != kCodecTag) {
    why = "built for '" + std::string(a->tag) + "', this brume is '" + kCodecTag + "'";
    dlclose(h);
    return nullptr;
  }
  return a;  // kept loaded for the life of the process
}
}  // namespace

const Api& api(const std::string& why_needed) {
  if (const Api* a = g_api.load(std::memory_order_acquire)) return *a;
  std::lock_guard<std::mutex> lock(g_mutex);
  if (const Api* a = g_api.load(std::memory_order_acquire)) return *a;
  std::string tried;
  const auto t0 = std::chrono::steady_clock::now();
  for (const std::string& p : module_candidates()) {
    std::string why;
    if (const Api* a = try_load(p, why)) {
      run_phases().codec_load_ms += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
      g_api.store(a, std::memory_order_release);
      return *a;
    }
    tried += "\n  " + p + ": " + why;
  }
  throw Error(why_needed + " needs brume's image-codec module (" + kModuleName +
              ", OpenImageIO), which could not be loaded from any of:" + tried +
              "\nbuild the brume_codec target (cmake --build), reinstall brume, or set BRUME_CODEC_MODULE to the "
              "module's path");
}

}  // namespace brume::codec
