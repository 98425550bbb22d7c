// A scene solved at the default parameters on two threads, checked valid and converged: shared by
// the solver's tests that read the mesh a viewer would get.
#pragma once

#include "hemibake/solver/solver.h"

#include <gtest/gtest.h>

namespace hemibake::solver {

inline Mesh solve(const Scene& scene) {
  EXPECT_EQ(validate(scene), "");
  Params params;
  params.threads = 2;
  Solver solver(scene, params);
  solver.run();
  EXPECT_TRUE(solver.stats().converged);
  return solver.mesh();
}

}  // namespace hemibake::solver
