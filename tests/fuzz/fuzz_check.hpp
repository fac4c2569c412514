#pragma once
// Shared by the fuzz targets: a check that aborts (libFuzzer and the corpus runner both report an abort as
// a failure, with the input that caused it), and the entry points every target defines.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>

#define FUZZ_CHECK(c)                                                                   \
  do {                                                                                  \
    if (!(c)) {                                                                         \
      std::fprintf(stderr, "FUZZ_CHECK failed: %s at %s:%d\n", #c, __FILE__, __LINE__); \
      std::abort();                                                                     \
    }                                                                                   \
  } while (0)

extern "C" int LLVMFuzzerInitialize(int* argc, char*** argv);
extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size);
