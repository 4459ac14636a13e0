// brume — the SIMD targets of the vector kernels (core/simd.hpp).
#include "core/simd.hpp"

#include <hwy/highway.h>
#include <hwy/targets.h>

namespace brume::simd {

std::vector<std::int64_t> targets() { return hwy::SupportedAndGeneratedTargets(); }

std::string target_name(std::int64_t target) { return hwy::TargetName(target); }

void force_target(std::int64_t target) { hwy::SetSupportedTargetsForTest(target); }

}  // namespace brume::simd
