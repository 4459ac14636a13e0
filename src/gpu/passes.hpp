// brume — a GPU pass as text (private to brume): its name, the shared topics
// it needs and its fragment body, and the registry of every linked pass.
// No GL here: the browser preview (`brume view`) serves the same sources
// the native context compiles (src/gpu/context.hpp).
#pragma once

#include <initializer_list>
#include <string>
#include <string_view>
#include <vector>

namespace brume::gpu {

// A pass's program: a name that identifies it in the cache, the shared topics
// it needs (by name: "diffusion_math", "haze_math"; see kTopics in
// context.cpp) and its fragment body. Specs are static constants beside the
// code that runs the pass.
struct PassSpec {
  const char* name;
  std::initializer_list<const char*> topics;
  const char* body;
};

// The whole fragment shader of a pass: the `#version 300 es` prelude, the
// topics it declares, its body; and the vertex shader every pass shares.
// The native programs and the browser preview compile these very strings.
std::string fragment_source(const PassSpec& spec);
const char* vertex_source();
// The names of a pass's samplers in declaration order: sampler i is bound to
// texture unit i.
std::vector<std::string> sampler_names(const char* body);

// Every pass of the linked effects, by name (the browser preview serves
// them); each effect's GPU file registers its specs with a PassRegistration.
const PassSpec* find_pass(std::string_view name);
struct PassRegistration {
  PassRegistration(std::initializer_list<const PassSpec*> specs);
};

}  // namespace brume::gpu
