// HEMIBAKE_DCHECK(cond): the solver's invariants, checked in Debug builds (NDEBUG undefined). A
// failed check prints file:line and the condition to stderr and aborts. In Release the condition
// is not evaluated (only type-checked), so checks may walk arrays without costing a shot anything.
#pragma once

#ifndef NDEBUG
#include <cstdio>
#include <cstdlib>

namespace hemibake::solver::detail {

[[noreturn]] inline void dcheck_failed(const char* file, int line, const char* condition) {
  std::fprintf(stderr, "%s:%d: HEMIBAKE_DCHECK failed: %s\n", file, line, condition);
  std::abort();
}

}  // namespace hemibake::solver::detail

#define HEMIBAKE_DCHECK(cond) \
  ((cond) ? static_cast<void>(0) : ::hemibake::solver::detail::dcheck_failed(__FILE__, __LINE__, #cond))
#else
#define HEMIBAKE_DCHECK(cond) static_cast<void>(sizeof(!(cond)))
#endif
