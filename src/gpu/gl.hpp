// brume — owners of OpenGL ES objects (private to src/gpu).
//
// Every GL object brume creates is held by one of these move-only owners, so
// that an exception anywhere in a render (a bad parameter found by a later
// pass, a driver error, std::bad_alloc while reading back) deletes what the
// render had made instead of leaking it on the context. Each kind keeps a
// process-wide count of live objects (brume::gpu_live_objects()), which the
// leak tests compare before and after a throwing render.
//
// Destructors call GL, so an owner must die on the thread that created it,
// before its context. An owner remembers the context it was made in and
// deletes its object there (AsCurrent), whichever context is current when it
// dies: GL names are per context, and a deletion under another context would
// delete that context's object of the same name.
#pragma once

#include <EGL/egl.h>
#include <GLES3/gl32.h>

#include <atomic>
#include <utility>

#include "brume/error.hpp"

namespace brume::gl {

enum Kind { kTexture, kFramebuffer, kProgram, kQuery, kSampler, kVertexArray, kKinds };

inline std::atomic<int>& live(Kind k) {
  static std::atomic<int> counts[kKinds];
  return counts[k];
}

// Failure injection for the leak tests (tests/test_gpu.cpp): when >= 0, the
// number of further GL objects make() may create before it throws
// brume::Error, as a driver that runs out of memory mid-render would
// (GL_OUT_OF_MEMORY). Every kind counts. -1 (the default) turns it off.
inline std::atomic<int>& fail_after() {
  static std::atomic<int> n{-1};
  return n;
}

// A thread's current context and surfaces (brume's contexts have none),
// saved to be made current again: the context an object was made in, or the
// one to return to.
struct Current {
  EGLDisplay dpy = EGL_NO_DISPLAY;
  EGLContext ctx = EGL_NO_CONTEXT;
  EGLSurface draw = EGL_NO_SURFACE, read = EGL_NO_SURFACE;
  static Current now() {
    return {eglGetCurrentDisplay(), eglGetCurrentContext(), eglGetCurrentSurface(EGL_DRAW),
            eglGetCurrentSurface(EGL_READ)};
  }
  bool make() const { return eglMakeCurrent(dpy, draw, read, ctx) == EGL_TRUE; }
};

// Makes `o` current for its lifetime where another context is, then makes
// the caller's current again (or none, where none was). ok() is false where
// `o` cannot be made current (destroyed, or current on another thread): its
// objects cannot be deleted from here, and nothing else must be deleted in
// their place.
class AsCurrent {
 public:
  explicit AsCurrent(const Current& o) : prev_(Current::now()), dpy_(o.dpy) {
    if (o.ctx == EGL_NO_CONTEXT || prev_.ctx == o.ctx) return;
    switched_ = o.make();
    ok_ = switched_;
  }
  ~AsCurrent() {
    if (!switched_) return;
    if (prev_.ctx != EGL_NO_CONTEXT) prev_.make();
    else eglMakeCurrent(dpy_, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
  }
  AsCurrent(const AsCurrent&) = delete;
  AsCurrent& operator=(const AsCurrent&) = delete;
  bool ok() const { return ok_; }

 private:
  Current prev_;
  EGLDisplay dpy_;
  bool switched_ = false, ok_ = true;
};

template <Kind K>
class Object {
 public:
  Object() = default;
  ~Object() { reset(); }
  Object(const Object&) = delete;
  Object& operator=(const Object&) = delete;
  Object(Object&& o) noexcept : id_(std::exchange(o.id_, 0)), owner_(o.owner_) {}
  Object& operator=(Object&& o) noexcept {
    if (this != &o) {
      reset();
      id_ = std::exchange(o.id_, 0);
      owner_ = o.owner_;
    }
    return *this;
  }

  // A new GL object of this kind (programs: glCreateProgram).
  static Object make() {
    for (int n = fail_after().load(); n >= 0; n = fail_after().load()) {
      if (n == 0) throw Error("GPU backend: injected failure (gl::fail_after, a test hook): no GL object created");
      if (fail_after().compare_exchange_weak(n, n - 1)) break;
    }
    Object o;
    switch (K) {
      case kTexture: glGenTextures(1, &o.id_); break;
      case kFramebuffer: glGenFramebuffers(1, &o.id_); break;
      case kProgram: o.id_ = glCreateProgram(); break;
      case kQuery: glGenQueries(1, &o.id_); break;
      case kSampler: glGenSamplers(1, &o.id_); break;
      case kVertexArray: glGenVertexArrays(1, &o.id_); break;
      default: break;
    }
    if (o.id_) ++live(K);
    o.owner_ = Current::now();
    return o;
  }

  GLuint id() const { return id_; }
  explicit operator bool() const { return id_ != 0; }
  // The context it was made in.
  const Current& owner() const { return owner_; }
  // Hands the object to an owner outside this layer (GpuImage), which must
  // delete it (in owner()'s context) and decrement live(K) itself: it stays
  // counted as live.
  GLuint release() { return std::exchange(id_, 0); }

  void reset() {
    if (!id_) return;
    const AsCurrent in(owner_);
    if (in.ok()) {
      switch (K) {
        case kTexture: glDeleteTextures(1, &id_); break;
        case kFramebuffer: glDeleteFramebuffers(1, &id_); break;
        case kProgram: glDeleteProgram(id_); break;
        case kQuery: glDeleteQueries(1, &id_); break;
        case kSampler: glDeleteSamplers(1, &id_); break;
        case kVertexArray: glDeleteVertexArrays(1, &id_); break;
        default: break;
      }
    }
    --live(K);
    id_ = 0;
  }

 private:
  GLuint id_ = 0;
  Current owner_;
};

using Texture = Object<kTexture>;
using Framebuffer = Object<kFramebuffer>;
using Program = Object<kProgram>;
using Query = Object<kQuery>;
using Sampler = Object<kSampler>;
using VertexArray = Object<kVertexArray>;

// Shaders live only between compile and link; owned all the same, so that a
// failed compile of the second stage does not leak the first.
class Shader {
 public:
  explicit Shader(GLenum type) : id_(glCreateShader(type)) {}
  ~Shader() {
    if (id_) glDeleteShader(id_);
  }
  Shader(const Shader&) = delete;
  Shader& operator=(const Shader&) = delete;
  GLuint id() const { return id_; }

 private:
  GLuint id_;
};

}  // namespace brume::gl
