// brume — the limits a read is held to before it allocates: the pixel count
// a header may declare (--max-pixels) and the memory this process may still
// take (MemAvailable, the cgroup's limit, ulimit -v).
#include <sys/resource.h>

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <string>

#include "brume/error.hpp"
#include "brume/io.hpp"
#include "io/io_internal.hpp"

namespace brume {

namespace {
std::atomic<std::uint64_t> g_max_pixels{default_max_pixels};

std::string mpx(std::uint64_t px) {
  char b[64];
  std::snprintf(b, sizeof b, "%.1f Mpx", static_cast<double>(px) / 1e6);
  return b;
}
std::string mib(std::uint64_t bytes) {
  char b[64];
  std::snprintf(b, sizeof b, "%.0f MiB", static_cast<double>(bytes) / (1024.0 * 1024.0));
  return b;
}

// A number from a one-line kernel file ("max" = no limit).
bool read_u64_file(const std::string& path, std::uint64_t& v) {
  std::ifstream f(path);
  std::string s;
  if (!(f >> s) || s == "max") return false;
  try {
    v = std::stoull(s);
  } catch (...) {
    return false;
  }
  return true;
}

// A "Key:   N kB" line of /proc/meminfo or /proc/self/status, in bytes.
bool read_kb_field(const std::string& path, const std::string& key, std::uint64_t& v) {
  std::ifstream f(path);
  std::string line;
  while (std::getline(f, line))
    if (line.compare(0, key.size(), key) == 0 && line.size() > key.size() && line[key.size()] == ':') {
      try {
        v = std::stoull(line.substr(key.size() + 1)) * 1024;
      } catch (...) {
        return false;
      }
      return true;
    }
  return false;
}

}  // namespace

void check_declared_size(const std::string& path, std::int64_t w, std::int64_t h, std::int64_t channels) {
  const std::uint64_t px = static_cast<std::uint64_t>(w) * static_cast<std::uint64_t>(h);
  if (px > max_pixels())
    throw Error("'" + path + "' declares " + std::to_string(w) + " x " + std::to_string(h) + " pixels (" + mpx(px) +
                "), over the limit of " + mpx(max_pixels()) +
                "; a corrupt or hostile header is the usual cause. If the file is genuine, raise the limit with "
                "--max-pixels " + std::to_string(px));
  if (channels > 1024)
    throw Error("'" + path + "' declares " + std::to_string(channels) +
                " channels; brume reads at most 1024 (a corrupt header?)");
}

std::uint64_t max_pixels() { return g_max_pixels.load(std::memory_order_relaxed); }
void set_max_pixels(std::uint64_t n) {
  if (n < 1) throw Error("--max-pixels must be at least 1");
  g_max_pixels.store(n, std::memory_order_relaxed);
}

std::uint64_t memory_available() {
  std::uint64_t avail = UINT64_MAX, v = 0;
  if (read_kb_field("/proc/meminfo", "MemAvailable", v)) avail = v;
  // cgroup v2: the process's group from /proc/self/cgroup ("0::/path").
  {
    std::ifstream f("/proc/self/cgroup");
    std::string line;
    while (std::getline(f, line)) {
      if (line.rfind("0::", 0) == 0) {
        const std::string dir = "/sys/fs/cgroup" + line.substr(3);
        std::uint64_t limit = 0, used = 0;
        if (read_u64_file(dir + "/memory.max", limit)) {
          read_u64_file(dir + "/memory.current", used);
          avail = std::min(avail, limit > used ? limit - used : 0);
        }
      }
    }
  }
  // cgroup v1 (an unlimited group reports a huge number, harmless here).
  {
    std::uint64_t limit = 0, used = 0;
    if (read_u64_file("/sys/fs/cgroup/memory/memory.limit_in_bytes", limit)) {
      read_u64_file("/sys/fs/cgroup/memory/memory.usage_in_bytes", used);
      avail = std::min(avail, limit > used ? limit - used : 0);
    }
  }
  struct rlimit rl {};
  if (::getrlimit(RLIMIT_AS, &rl) == 0 && rl.rlim_cur != RLIM_INFINITY) {
    std::uint64_t vm = 0;
    read_kb_field("/proc/self/status", "VmSize", vm);
    const std::uint64_t lim = rl.rlim_cur;
    avail = std::min(avail, lim > vm ? lim - vm : 0);
  }
  return avail;
}

void check_memory(std::uint64_t bytes, const std::string& what) {
  const std::uint64_t avail = memory_available();
  if (bytes > avail)
    throw Error(what + " needs about " + mib(bytes) + " of memory but this process may use only " + mib(avail) +
                " more (the least of MemAvailable, the cgroup limit and ulimit -v); free memory, raise the limit "
                "or work on a smaller image");
}

std::string out_of_memory_message() {
  return "out of memory: an allocation failed although the checks before the work passed (memory is shared with "
         "other processes); this process may now use " +
         mib(memory_available()) +
         " more (the least of MemAvailable, the cgroup limit and ulimit -v): free memory, raise the limit or work on "
         "a smaller input";
}

}  // namespace brume
