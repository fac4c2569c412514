#pragma once
// Counting global allocator for tests that prove a real-time path never allocates. Include it in exactly
// one translation unit of a test executable (it replaces the global operator new/delete). Every unaligned
// form is replaced, so that no pairing mixes these with a sanitizer's own allocator. GCC cannot see that
// the replacements pair malloc with free, hence the pragma.
#include <atomic>
#include <cstdlib>
#include <new>

#pragma GCC diagnostic ignored "-Wmismatched-new-delete"

namespace gearpulse::test {
inline std::atomic<bool> g_counting{true};  // allocations are counted while this is set
inline std::atomic<long> g_allocations{0};

inline void* counted_malloc(std::size_t size) noexcept {
  if (g_counting.load(std::memory_order_relaxed)) g_allocations.fetch_add(1, std::memory_order_relaxed);
  return std::malloc(size ? size : 1);
}
}  // namespace gearpulse::test

void* operator new(std::size_t size) {
  if (void* p = gearpulse::test::counted_malloc(size)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t size) {
  if (void* p = gearpulse::test::counted_malloc(size)) return p;
  throw std::bad_alloc();
}
void* operator new(std::size_t size, const std::nothrow_t&) noexcept {
  return gearpulse::test::counted_malloc(size);
}
void* operator new[](std::size_t size, const std::nothrow_t&) noexcept {
  return gearpulse::test::counted_malloc(size);
}
void operator delete(void* p) noexcept {
  std::free(p);
}
void operator delete[](void* p) noexcept {
  std::free(p);
}
void operator delete(void* p, std::size_t) noexcept {
  std::free(p);
}
void operator delete[](void* p, std::size_t) noexcept {
  std::free(p);
}
void operator delete(void* p, const std::nothrow_t&) noexcept {
  std::free(p);
}
void operator delete[](void* p, const std::nothrow_t&) noexcept {
  std::free(p);
}
