// brume::Image's constructors: the buffer is reserved, given the huge-page
// hint (src/core/huge_pages.hpp), then filled -- the fill is the first touch.
#include "brume/image.hpp"

#include <cstdint>

#include "core/huge_pages.hpp"

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace brume {

namespace detail {
void advise_huge_pages(void* p, std::size_t bytes) {
#if defined(__linux__) && defined(MADV_HUGEPAGE)
  if (bytes < kHugePageBytes) return;
  const auto b = reinterpret_cast<std::uintptr_t>(p);
  const std::uintptr_t lo = (b + kHugePageBytes - 1) & ~(kHugePageBytes - 1);
  const std::uintptr_t hi = (b + bytes) & ~(kHugePageBytes - 1);
  if (hi > lo) ::madvise(reinterpret_cast<void*>(lo), hi - lo, MADV_HUGEPAGE);  // a hint: failure is harmless
#else
  (void)p, (void)bytes;
#endif
}
}  // namespace detail

Image::Image(int w, int h, int c, float fill) : width(w), height(h), channels(c) {
  const std::size_t n = static_cast<std::size_t>(w) * h * c;
  detail::reserve_huge(data, n);
  data.resize(n, fill);
}

Image::Image(const Image& o) : width(o.width), height(o.height), channels(o.channels) {
  detail::reserve_huge(data, o.data.size());
  data.assign(o.data.begin(), o.data.end());
}

Image& Image::operator=(const Image& o) {
  if (this == &o) return *this;
  width = o.width, height = o.height, channels = o.channels;
  if (o.data.size() > data.capacity()) {
    std::vector<float>().swap(data);  // free the old buffer before the new one: never hold both
    detail::reserve_huge(data, o.data.size());
  }
  data.assign(o.data.begin(), o.data.end());
  return *this;
}

}  // namespace brume
