// Transparent huge pages for large fresh buffers.
//
// A fresh allocation's pages are mapped on first touch, one page fault per
// 4 kB page. On the virtual machines brume is measured on a fault costs
// ~10 us, so a 1600x1120 RGBA float image (28.7 MB, 7000 pages) costs ~80 ms
// of faults before its first value is written -- more than the diffusion of
// that image. Asking Linux to back the buffer with 2 MB pages (madvise
// MADV_HUGEPAGE; hosts whose /sys/kernel/mm/transparent_hugepage/enabled is
// "madvise", Debian's default, honour it only when asked) turns those 7000
// faults into 14: 6.5 ms instead of 78 ms for that buffer on the AMD EPYC
// host (docs/performance.md). It is a hint: the bytes, their values and every
// result are unchanged, and a host with huge pages "never" (or not Linux)
// ignores it.
#pragma once

#include <cstddef>
#include <vector>

namespace brume::detail {

// Buffers smaller than this are left alone (no whole 2 MB page inside).
inline constexpr std::size_t kHugePageBytes = std::size_t{2} << 20;

// Ask for huge pages on the whole 2 MB pages inside [p, p + bytes) before the
// memory is first touched. Harmless if the range was touched already (its
// mapped pages stay) or the kernel says no.
void advise_huge_pages(void* p, std::size_t bytes);

// v.reserve(n) with the hint on the new (untouched) capacity when it grows.
template <class T>
void reserve_huge(std::vector<T>& v, std::size_t n) {
  if (n <= v.capacity()) return;
  v.reserve(n);
  advise_huge_pages(v.data(), n * sizeof(T));
}

}  // namespace brume::detail
