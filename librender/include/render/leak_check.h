// The LeakSanitizer pause around GL work. Mesa keeps a few allocations for the life of the process
// (libgio at driver load, llvmpipe's JIT on the first draws) that LeakSanitizer reports at exit as
// leaks; they are not ours and cannot be freed, so an ASan build would always fail its exit status.
// Wrapping the GL calls (context, renderer construction, upload, render, read-back) in a
// GlLeakCheckPause keeps that status about the program's own leaks. Outside ASan builds it does
// nothing and costs nothing.
#pragma once

// AddressSanitizer builds: GCC defines __SANITIZE_ADDRESS__, Clang answers __has_feature.
#if defined(__SANITIZE_ADDRESS__)
#define TERRAIN_RUNTIME_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define TERRAIN_RUNTIME_ASAN 1
#endif
#endif
#if defined(TERRAIN_RUNTIME_ASAN)
#include <sanitizer/lsan_interface.h>
#endif

namespace terrain::render {

// Allocations the calling thread makes while one lives are never reported as leaks; other threads'
// allocations still are. Pauses nest.
class GlLeakCheckPause {
 public:
  GlLeakCheckPause() {
#if defined(TERRAIN_RUNTIME_ASAN)
    __lsan_disable();
#endif
  }
  ~GlLeakCheckPause() {
#if defined(TERRAIN_RUNTIME_ASAN)
    __lsan_enable();
#endif
  }
  GlLeakCheckPause(const GlLeakCheckPause&) = delete;
  GlLeakCheckPause& operator=(const GlLeakCheckPause&) = delete;
};

}  // namespace terrain::render
