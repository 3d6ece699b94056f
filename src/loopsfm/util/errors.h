#pragma once
// Errors and checks.
//
// User-facing problems (bad flags, missing files, corrupt input) throw a typed
// loopsfm::Error subclass whose message says what was wrong and what to do; the CLI
// prints it and exits with code 2. Internal invariants use LOOPSFM_CHECK*, which abort
// with file:line, because a broken invariant is a bug, not a user error.

#include <stdexcept>
#include <string>

#include <fmt/format.h>

namespace loopsfm {

// Base of every error caused by user input. what() is meant to be shown to the user.
class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// An option or argument has a value outside its valid range.
class InvalidArgument : public Error {
 public:
  using Error::Error;
};

// An input file or folder is missing, unreadable or not in the expected format.
class InputError : public Error {
 public:
  using Error::Error;
};

// A database or output file cannot be used (not ours, read-only, corrupt).
class StorageError : public Error {
 public:
  using Error::Error;
};

// The user asked the run to stop (cancel callback); finished work is kept.
class Cancelled : public Error {
 public:
  using Error::Error;
};

namespace internal {
[[noreturn]] void CheckFailed(const char* file, int line, const char* condition,
                              const std::string& message);
}  // namespace internal

}  // namespace loopsfm

// Aborts with file:line when an internal invariant does not hold.
#define LOOPSFM_CHECK(cond)                                                     \
  do {                                                                          \
    if (!(cond)) ::loopsfm::internal::CheckFailed(__FILE__, __LINE__, #cond, ""); \
  } while (false)

#define LOOPSFM_CHECK_MSG(cond, ...)                                     \
  do {                                                                   \
    if (!(cond))                                                         \
      ::loopsfm::internal::CheckFailed(__FILE__, __LINE__, #cond,        \
                                       ::fmt::format(__VA_ARGS__));      \
  } while (false)

#define LOOPSFM_CHECK_EQ(a, b) LOOPSFM_CHECK((a) == (b))
#define LOOPSFM_CHECK_LT(a, b) LOOPSFM_CHECK((a) < (b))
#define LOOPSFM_CHECK_LE(a, b) LOOPSFM_CHECK((a) <= (b))
#define LOOPSFM_CHECK_GT(a, b) LOOPSFM_CHECK((a) > (b))
#define LOOPSFM_CHECK_GE(a, b) LOOPSFM_CHECK((a) >= (b))

// Throws loopsfm::InvalidArgument with a formatted message when an option is out of range.
#define LOOPSFM_REQUIRE_OPTION(cond, ...)                                  \
  do {                                                                     \
    if (!(cond)) throw ::loopsfm::InvalidArgument(::fmt::format(__VA_ARGS__)); \
  } while (false)
