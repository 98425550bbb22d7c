// Bake job parameters as they travel over the wire: query strings, JSON, the command line.
#pragma once

#include "hemibake/protocol/gltf.h"
#include "hemibake/solver/solver.h"

#include <map>
#include <string>

namespace hemibake::protocol {

/// What a bake is asked to do. `write.method` names the method: empty for the solver's own (aa
/// or classical, in params.method), "hr" for hierarchical radiosity, "reference" for the aa mesh
/// with path-traced vertex radiosity.
struct JobSpec {
  solver::Params params;
  WriteOptions write;
  uint32_t rays = 4;       ///< hr: visibility rays per link
  uint32_t samples = 256;  ///< reference: paths per vertex
};

/// Applies named parameters (the command line's names without dashes: method (aa, classical, hr,
/// reference), resolution, feps, aeps, beps, convergence, max_shots, max_elements, threads, reuse,
/// cluster_size, shot_cache_mb, rays, samples, draco, position_bits, texcoord_bits, draco_speed, exposure) to `spec`. Returns an empty string, or a message naming
/// the first unknown or bad parameter.
std::string apply_params(const std::map<std::string, std::string>& values, JobSpec& spec);

/// The parameters as a JSON object text with every field, in a fixed order (equal specs give
/// equal text: a cache key).
std::string params_json(const JobSpec& spec);

/// Parses what params_json wrote, or a JSON object of the same names with string or number
/// values. Returns an empty string or a message.
std::string parse_params_json(const std::string& text, JobSpec& spec);

}  // namespace hemibake::protocol
