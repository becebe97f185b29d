// Which sanitizer instruments this test binary, for the few tests whose measurement it changes
// (RSS under ASan's redzones and quarantine, address-space limits under any sanitizer's shadow).
// gcc defines __SANITIZE_ADDRESS__ / __SANITIZE_THREAD__; clang 14 defines neither and answers
// __has_feature instead, so both are asked (the fuzz build and scripts/sanitize tsan are clang).
#pragma once

#if defined(__has_feature)
#if __has_feature(address_sanitizer)
#define CLOUDCAST_TEST_ASAN 1
#endif
#if __has_feature(thread_sanitizer)
#define CLOUDCAST_TEST_TSAN 1
#endif
#if __has_feature(memory_sanitizer)
#define CLOUDCAST_TEST_MSAN 1
#endif
#endif
#if defined(__SANITIZE_ADDRESS__) && !defined(CLOUDCAST_TEST_ASAN)
#define CLOUDCAST_TEST_ASAN 1
#endif
#if defined(__SANITIZE_THREAD__) && !defined(CLOUDCAST_TEST_TSAN)
#define CLOUDCAST_TEST_TSAN 1
#endif

namespace cloudcast::testing {

inline constexpr bool kUnderAddressSanitizer =
#ifdef CLOUDCAST_TEST_ASAN
    true;
#else
    false;
#endif

inline constexpr bool kUnderAnySanitizer =
#if defined(CLOUDCAST_TEST_ASAN) || defined(CLOUDCAST_TEST_TSAN) || defined(CLOUDCAST_TEST_MSAN)
    true;
#else
    false;
#endif

}  // namespace cloudcast::testing
