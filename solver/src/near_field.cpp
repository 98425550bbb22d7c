// Rules for receivers close to a shooting piece, where the hemicube at its centre sees them
// poorly.
#include "solver_impl.h"

#include "hemibake/solver/hemicube.h"

#include <glm/common.hpp>
#include <glm/geometric.hpp>

namespace hemibake::solver {

// Whether a patch whose back the piece's centre sees (one that absorbs: not back_hidden), in front
// of the piece and within one of its diameters, takes at least kAbsorberShare of the centre's light.
bool Solver::Impl::absorber_close(const Piece& piece) const {
  const glm::dvec3& c = piece.centre;
  const double r = piece.diameter;
  const double eps = 1e-9 * prep.diagonal;
  std::vector<uint32_t> nodes{0};
  while (!nodes.empty()) {
    const BoxNode& node = tree[nodes.back()];
    nodes.pop_back();
    const glm::dvec3 gap = glm::max(node.lo - c, glm::max(c - node.hi, glm::dvec3(0.0)));
    if (glm::dot(gap, gap) > r * r) continue;
    if (node.child != kNone) {
      nodes.push_back(node.child);
      nodes.push_back(node.child + 1);
      continue;
    }
    for (uint32_t i = node.begin; i < node.end; ++i) {
      const uint32_t q = tree_patch[i];
      if (prep.back_hidden[q] || p_shooting[q] == shooting_stamp) continue;
      if (glm::dot(prep.normal[q], c - patches[q].corners[0]) >= -eps) continue;  // not its back
      const glm::dvec3 d = glm::max(p_lo[q] - c, glm::max(c - p_hi[q], glm::dvec3(0.0)));
      const double d2 = glm::dot(d, d);
      if (d2 > r * r) continue;
      // The form factor from the centre to the patch cut to the piece's front side: the share of
      // the centre's light it takes (a back seen edge-on takes little).
      std::array<glm::dvec3, 8> cut{};
      uint32_t m = 0;
      const uint32_t cc = patches[q].corner_count;
      for (uint32_t k = 0; k < cc; ++k) {
        const glm::dvec3& a = patches[q].corners[k];
        const glm::dvec3& b = patches[q].corners[(k + 1) % cc];
        const double da = glm::dot(piece.normal, a - c), db = glm::dot(piece.normal, b - c);
        if (da > eps) cut[m++] = a;
        if ((da > eps) != (db > eps)) cut[m++] = a + (b - a) * ((da - eps) / (da - db));
      }
      if (m >= 3 && point_polygon_form_factor(c, piece.normal, std::span(cut.data(), m)) >= kAbsorberShare) return true;
    }
  }
  return false;
}

}  // namespace hemibake::solver
