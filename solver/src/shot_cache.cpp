// Replays: a shooter that shoots again reuses the form factors of its last shot (replay), which a
// fresh shot records piece by piece (record_piece) with the headroom that keeps a replay exact.
#include "solver_impl.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace hemibake::solver {

// A shooter that shoots again (its patches received light since) places the same hemicubes and, as
// long as none of its receivers has been split since, finds the same form factors: a split
// occluder's children hide exactly what it hid. A replay takes them from the last shot's record and
// only recomputes each piece's unshot radiosity. Every piece must shoot no more than when it was
// recorded, in every channel: the refinement near the shooter, the hemicubes' resolution and the
// subdivision criteria all ask less of a weaker shot, so it would have placed no finer hemicubes and
// split nothing more (the recorded shot ended with a round that split nothing).
bool Solver::Impl::replay(uint32_t unit) {
  if (u_record.empty()) return false;
  ShotRecord& r = u_record[unit];
  if (r.pieces.empty()) return false;
  HEMIBAKE_DCHECK(r.consistent());
  // Receivers split since need form factors for their children. When they are few, the rest is
  // replayed and the children are shot anew from the same shooter, its hemicubes seeing only what
  // may hide them (as near-field hemicubes do); otherwise the whole shot is made anew.
  // A covered piece's leaf split since: a fresh shot would cut it along its children.
  for (uint32_t e : r.covered)
    if (e_child[e] != kNone) return false;
  std::vector<uint8_t> stale;
  const size_t stale_count = mark_stale(r, stale);
  if (stale_count * 4 > r.entries()) {
    keep_record(unit, {});  // splits are for good: it never replays again
    return false;
  }
  std::vector<glm::dvec3> dBs;
  if (!replayed_radiosities(r, dBs)) return false;
  for (size_t i = 0; i < r.pieces.size(); ++i) {
    const ShotRecord::Piece& rp = r.pieces[i];
    gap_share = covered_share(std::span(r.src.data() + rp.src_begin, rp.src_end - rp.src_begin));
    ShooterShape shape = rp.shape;
    shape.src = std::span(r.src.data() + rp.src_begin, rp.src_end - rp.src_begin);
    shooter_shape = &shape;
    ++grid_shooter;
    // A piece's receivers are distinct (each piece's were its shot's accepted leaves).
    receive_each(rp.recv_end - rp.recv_begin, dBs[i], [&](size_t j) { return r.recv[rp.recv_begin + j]; },
                 [&](size_t j) { return stale[rp.recv_begin + j] ? 0.0 : static_cast<double>(r.f[rp.recv_begin + j]); }, false);
    shooter_shape = nullptr;
    gap_share = 0.0;
  }
  if (stale_count == 0) return true;

  const ShotRecord part = reshoot_split(unit, r);
  // The record now holds the replayed receivers and the partial shot's pieces. Each partial shot
  // adds pieces (with the sources of the shooter's own): past four times the fresh shot's, the
  // record is dropped, and the next shot makes a compact one.
  if (record_broken || r.pieces.size() + part.pieces.size() > 4 * r.fresh_pieces) {
    keep_record(unit, {});
    return true;
  }
  ShotRecord merged;
  merged.fresh_pieces = r.fresh_pieces;
  for (const ShotRecord::Piece& rp : r.pieces) merged.append(r, rp, stale.data());
  for (const ShotRecord::Piece& rp : part.pieces) merged.append(part, rp, nullptr);
  merged.covered = r.covered;
  for (uint32_t e : part.covered)
    if (std::find(merged.covered.begin(), merged.covered.end(), e) == merged.covered.end()) merged.covered.push_back(e);
  HEMIBAKE_DCHECK(merged.consistent());
  keep_record(unit, std::move(merged));
  return true;
}

// Flags the record's receivers split since it was made (`stale`, per entry: recv's, then dark's),
// and marks them (e_mark = mark) for reshoot_split. A shot that split a receiver recorded it in its
// earlier pieces and its children in later ones: the children are shot anew from the whole
// shooter, so none of their entries replays either. So everything below a split receiver is
// marked too (its subtree holds only what was split since), and an entry is stale when it is
// marked: a walk up from every entry took 2.7 % of a profile's samples on the Blender cluttered
// room (52 000-entry records). Returns how many entries are stale.
size_t Solver::Impl::mark_stale(const ShotRecord& r, std::vector<uint8_t>& stale) {
  stale.assign(r.entries(), 0);
  ++mark;
  std::vector<uint32_t> todo;
  auto mark_below = [&](uint32_t e) {
    if (e_child[e] == kNone || e_mark[e] == mark) return;
    todo.push_back(e);
    while (!todo.empty()) {
      const uint32_t x = todo.back();
      todo.pop_back();
      if (e_mark[x] == mark) continue;
      e_mark[x] = mark;
      if (e_child[x] != kNone)
        for (uint32_t k = 0; k < 4; ++k) todo.push_back(e_child[x] + k);
    }
  };
  for (uint32_t e : r.recv) mark_below(e);
  for (const ShotRecord::Piece& p : r.pieces) r.for_dark(p, [&](uint32_t e, size_t) { mark_below(e); });
  size_t stale_count = 0;
  for (size_t k = 0; k < r.recv.size(); ++k)
    if (e_mark[r.recv[k]] == mark) stale[k] = 1, ++stale_count;
  for (const ShotRecord::Piece& p : r.pieces)
    r.for_dark(p, [&](uint32_t e, size_t k) {
      if (e_mark[e] == mark) stale[r.recv.size() + k] = 1, ++stale_count;
    });
  HEMIBAKE_DCHECK(stale_count <= r.entries());
  return stale_count;
}

// The unshot radiosity each recorded piece shoots now (`dBs`). False when a piece grew past its
// headroom or would now shoot from its children.
bool Solver::Impl::replayed_radiosities(const ShotRecord& r, std::vector<glm::dvec3>& dBs) {
  dBs.assign(r.pieces.size(), glm::dvec3(0.0));
  for (size_t i = 0; i < r.pieces.size(); ++i) {
    const ShotRecord::Piece& rp = r.pieces[i];
    glm::dvec3 power(0.0);
    for (uint32_t k = rp.src_begin; k < rp.src_end; ++k)
      for_leaves(r.src[k], [&](uint32_t e) { power += e_unshot[e] * e_area[e]; });
    dBs[i] = power / rp.src_area;
    HEMIBAKE_DCHECK(dBs[i].x >= 0.0 && dBs[i].y >= 0.0 && dBs[i].z >= 0.0);
    // The most any channel grew: every decision of the shot is a sum of channels with non-negative
    // weights, so it grew by at most this factor.
    double growth = 0.0;
    for (int c = 0; c < 3; ++c) {
      if (dBs[i][c] <= 0.0) continue;
      growth = rp.dB[c] > 0.0 ? std::max(growth, dBs[i][c] / rp.dB[c]) : std::numeric_limits<double>::infinity();
    }
    if (std::isinf(growth) || growth > rp.headroom) return false;
    // A piece that would now shoot from its children (shoot_node) cannot replay as one.
    if (rp.src_end - rp.src_begin == 1 && e_child[r.src[rp.src_begin]] != kNone && rp.src_area == rp.area &&
        channel_sum(dBs[i]) * rp.area >= params.feps * emitted_power && uneven_piece(r.src[rp.src_begin]))
      return false;
  }
  return true;
}

// Shoots the unit anew to the receivers marked by mark_stale, each once and none below another
// (the shot expands them to their leaves), and returns the record of that partial shot.
Solver::Impl::ShotRecord Solver::Impl::reshoot_split(uint32_t unit, const ShotRecord& r) {
  std::vector<uint32_t> redo;
  auto take = [&](uint32_t e) {
    if (e_mark[e] != mark) return;
    bool below = false;
    for (uint32_t x = e_parent[e]; x != kNone && !below; x = e_parent[x]) below = e_mark[x] == mark;
    if (!below) redo.push_back(e);
  };
  for (uint32_t e : r.recv) take(e);
  for (const ShotRecord::Piece& p : r.pieces) r.for_dark(p, [&](uint32_t e, size_t) { take(e); });
  std::sort(redo.begin(), redo.end());
  redo.erase(std::unique(redo.begin(), redo.end()), redo.end());
  ShotRecord part;
  recording = &part;
  record_broken = false;
  grow_scratch();
  if (unit_node[unit] == kNone) shoot_patch(unit_patch[unit], redo, false);
  else shoot_cluster(unit_node[unit], redo, false, 0);
  recording = nullptr;
  ++stats.replays_reshot;
  return part;
}

// Appends `from`'s piece `np` with its receivers but those flagged in `skip` (may be null; per
// entry of `from`, as mark_stale's); a piece left with no receivers is dropped.
void Solver::Impl::ShotRecord::append(const ShotRecord& from, Piece np, const uint8_t* skip) {
  const Piece was = np;
  const uint32_t src_begin = np.src_begin, src_end = np.src_end, recv_begin = np.recv_begin, recv_end = np.recv_end;
  np.recv_begin = static_cast<uint32_t>(recv.size());
  np.dark_begin = static_cast<uint32_t>(dark.size());
  np.dark_first = static_cast<uint32_t>(dark_count);
  for (uint32_t k = recv_begin; k < recv_end; ++k) {
    if (skip != nullptr && skip[k]) continue;
    recv.push_back(from.recv[k]);
    f.push_back(from.f[k]);
  }
  uint32_t last = 0;
  from.for_dark(was, [&](uint32_t e, size_t k) {
    if (skip == nullptr || !skip[from.recv.size() + k]) add_dark(last, e);
  });
  np.recv_end = static_cast<uint32_t>(recv.size());
  np.dark_end = static_cast<uint32_t>(dark.size());
  if (np.recv_end == np.recv_begin && np.dark_end == np.dark_begin) return;
  np.src_begin = static_cast<uint32_t>(src.size());
  src.insert(src.end(), from.src.begin() + src_begin, from.src.begin() + src_end);
  np.src_end = static_cast<uint32_t>(src.size());
  pieces.push_back(np);
}

// The pieces' receiver ranges follow one another and cover recv (f alongside) and dark; their
// source ranges lie in src; every piece shot from an area.
bool Solver::Impl::ShotRecord::consistent() const {
  if (f.size() != recv.size()) return false;
  uint32_t recv_at = 0, dark_at = 0;
  size_t unlit = 0;
  for (const Piece& p : pieces) {
    if (p.recv_begin != recv_at || p.recv_end < p.recv_begin) return false;
    if (p.dark_begin != dark_at || p.dark_end < p.dark_begin || p.dark_first != unlit) return false;
    if (p.src_begin > p.src_end || p.src_end > src.size()) return false;
    if (!(p.src_area > 0.0 && p.area > 0.0)) return false;
    for_dark(p, [&](uint32_t, size_t) { ++unlit; });
    recv_at = p.recv_end;
    dark_at = p.dark_end;
  }
  return recv_at == recv.size() && dark_at == dark.size() && unlit == dark_count;
}

// Records a piece's shot: its sources, every accepted receiver with F(element -> piece), and its
// headroom (piece_headroom).
void Solver::Impl::record_piece(const Piece& piece, double split_room, const std::vector<uint32_t>& accepted) {
  ShotRecord& r = *recording;
  // A record that could not be kept is not built further, and one that outgrows the cache is
  // dropped as it grows: a shot of thousands of pieces (each listing its receivers) would otherwise
  // hold gigabytes until its end, only for keep_record to refuse it.
  if (record_broken) return;
  const size_t budget = static_cast<size_t>(params.shot_cache_mb) << 20;
  if (r.bytes() + accepted.size() * (sizeof(uint32_t) + sizeof(float)) + piece.src.size() * sizeof(uint32_t) > budget) {
    record_broken = true;
    r = ShotRecord{};
    return;
  }
  ShotRecord::Piece rp;
  rp.src_begin = static_cast<uint32_t>(r.src.size());
  r.src.insert(r.src.end(), piece.src.begin(), piece.src.end());
  rp.src_end = static_cast<uint32_t>(r.src.size());
  rp.recv_begin = static_cast<uint32_t>(r.recv.size());
  rp.dark_begin = static_cast<uint32_t>(r.dark.size());
  rp.dark_first = static_cast<uint32_t>(r.dark_count);
  // Unlit receivers too: once split, their children may be lit (a near receiver's exact form
  // factor, a different route to the sub-pieces), so a replay must know to shoot them anew.
  uint32_t last = 0;
  for (uint32_t e : accepted) {
    const float f = static_cast<float>(std::max(0.0, f_recv[e]));
    if (f > 0.0f) {
      r.recv.push_back(e);
      r.f.push_back(f);
    } else {
      r.add_dark(last, e);
    }
  }
  rp.recv_end = static_cast<uint32_t>(r.recv.size());
  rp.dark_end = static_cast<uint32_t>(r.dark.size());
  rp.src_area = piece.src_area;
  rp.area = piece.area;
  rp.dB = piece.dB;
  rp.headroom = piece_headroom(piece, split_room, accepted);
  rp.shape = shape_of(piece);
  r.pieces.push_back(rp);
}

// The least factor on dB at which a fresh shot of this piece would decide anything differently
// from this one: the split criteria (`split_room`, from refine); power thresholds: refinement of
// weak pieces, the straddle rule, finer hemicubes for strong pieces (sharp_shadows, or objects that
// asked for them); and
// the close receivers left to this hemicube because the point view's error seemed small.
double Solver::Impl::piece_headroom(const Piece& piece, double split_room, const std::vector<uint32_t>& accepted) {
  const double power = piece.power;
  double headroom = split_room;
  const bool patch_piece = piece.points.size() <= 4;
  // Two rules save work rather than decide structure, and a replay may exceed them by up to
  // kSavingRuleSlack: a weak piece that was not refined (its close receivers took exact form
  // factors) stays so up to twice FEPS of the emitted power, and a close receiver left to this
  // hemicube because its point view errs by under a quarter of the radiosity tolerance stays so
  // until half of it.
  if (patch_piece && !piece.may_refine && piece.depth < kMaxShooterDepth)
    lower_headroom(headroom, kSavingRuleSlack * params.feps * emitted_power, power);
  // A weak cluster piece did not look for absorbers close in front of it (shoot_piece).
  if (!patch_piece && piece.may_refine && power < params.feps * emitted_power)
    lower_headroom(headroom, kSavingRuleSlack * params.feps * emitted_power, power);
  if (patch_piece && power < kStraddlePower * emitted_power) lower_headroom(headroom, kStraddlePower * emitted_power, power);
  if (params.method == Method::kAntiAliased) {
    if ((params.sharp_shadows || objects_want_finer) && !piece.volume && power < kSharpPower * emitted_power)
      lower_headroom(headroom, kSharpPower * emitted_power, power);
  }
  if (piece.may_refine)
    headroom = least_over(accepted.size(), headroom, [&](size_t i, double& room) {
      if (is_close(piece, accepted[i]))
        lower_headroom(room, kSavingRuleSlack * kNearError * b_tolerance, near_error(piece, accepted[i]));
    });
  return headroom;
}

// Puts `record` in place of the unit's record, if the records' memory allows.
void Solver::Impl::keep_record(uint32_t unit, ShotRecord record) {
  if (!u_record.empty()) {
    HEMIBAKE_DCHECK(unit < u_record.size() && record_bytes >= u_record[unit].bytes());
    record_bytes -= u_record[unit].bytes();
    u_record[unit] = ShotRecord{};
  }
  if (record.pieces.empty()) return;
  record.pieces.shrink_to_fit();
  record.src.shrink_to_fit();
  record.recv.shrink_to_fit();
  record.dark.shrink_to_fit();
  record.f.shrink_to_fit();
  record.covered.shrink_to_fit();
  if (record_bytes + record.bytes() > static_cast<size_t>(params.shot_cache_mb) << 20) return;
  if (u_record.empty()) u_record.resize(unit_node.size());
  record_bytes += record.bytes();
  u_record[unit] = std::move(record);
}

}  // namespace hemibake::solver
