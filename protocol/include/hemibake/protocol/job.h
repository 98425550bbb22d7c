// A bake job's parameters, the one place that names them: the command line (--max-shots), the
// wire (query strings, form fields, JSON: max_shots), their limits, defaults and help text, and the
// cache key all come from one table. Also the progress a job reports.
#pragma once

#include "hemibake/protocol/gltf.h"
#include "hemibake/protocol/method.h"
#include "hemibake/solver/solver.h"

#include <glm/vec3.hpp>

#include <map>
#include <optional>
#include <span>
#include <string>

namespace hemibake::protocol {

/// What a bake is asked to do.
/// Presets of the solver's settings that trade time for quality (see README, "Quality"): a preset
/// is applied first, and parameters given with it override it.
enum class Quality : uint8_t { kDraft, kDefault, kHigh };

const char* to_string(Quality quality);
std::optional<Quality> quality_from(std::string_view name);

/// The solver's settings at the default preset: the library's defaults with light pools (the
/// library leaves them off, and so does the draft preset).
inline solver::Params default_solver_params() {
  solver::Params p;
  p.pools = true;
  return p;
}

struct JobSpec {
  Method method = Method::kAntiAliased;
  Quality quality = Quality::kDefault;  ///< the preset the settings started from
  solver::Params params = default_solver_params();  ///< the solver's settings; params.method is not
                                                    ///< read: `method` decides (solver_params()
                                                    ///< gives the solver what it runs)
  WriteOptions write;      ///< the output file
  uint32_t rays = 4;       ///< hr: visibility rays per link
  uint32_t samples = 256;  ///< reference: paths per vertex
  glm::dvec3 sky{0.0};     ///< radiance of a uniform sky around the scene (aa, classical, reference)
};

/// The solver's parameters for `spec`, with the form-factor mode its method needs (reference bakes
/// the aa mesh first).
solver::Params solver_params(const JobSpec& spec);

/// One job parameter. Values are numbers (a method's index in Method, a tone's in Tone, a flag's 0
/// or 1).
struct ParamInfo {
  enum class Kind : uint8_t { kMethod, kWhole, kNumber, kFlag, kColour, kQuality, kTone };
  const char* name;     ///< on the wire: query, form field, JSON key
  const char* flag;     ///< on the command line, without the dashes; a kFlag that defaults on is
                        ///< turned off by --no-FLAG, any other parameter takes --FLAG VALUE
  Kind kind;
  double min, max;      ///< accepted range of a kWhole or kNumber (inclusive; the solver's own
                        ///< validate() adds what a range cannot say, such as an even resolution)
  const char* help;     ///< one line for --help and the API description
  double (*get)(const JobSpec&);  ///< a kColour: the mean of its channels
  void (*set)(JobSpec&, double);  ///< a kColour: grey
  /// A kColour ("R,G,B", or one number for grey; each channel in [min, max]): its channels.
  glm::dvec3 (*get_colour)(const JobSpec&) = nullptr;
  void (*set_colour)(JobSpec&, const glm::dvec3&) = nullptr;
};

/// Every parameter, in the fixed order of params_json.
std::span<const ParamInfo> param_table();

/// The parameter with this wire name, or null.
const ParamInfo* find_param(std::string_view name);

/// Reads `text` as a value of `param` into `value` (a kColour: the mean of its channels).
/// Returns an empty string, or what is wrong for the user after the parameter's name ("must be a
/// whole number from 1 to 1024 (got '0')").
std::string parse_param_value(const ParamInfo& param, const std::string& text, double& value);

/// Reads `text` as a kColour's value: "R,G,B" or one number for all three channels.
std::string parse_colour_value(const ParamInfo& param, const std::string& text, glm::dvec3& value);

/// Applies named values (wire names, text as typed: "aa", "0.001", "true"/"false"/"1"/"0"/"yes"/
/// "no") to `spec`. Returns an empty string, or a message naming the first unknown or bad
/// parameter; the solver's validate() runs last.
std::string apply_params(const std::map<std::string, std::string>& values, JobSpec& spec);

/// The parameters as a JSON object text with every field of param_table(), in its order (equal
/// specs give equal text: this is the cache key, so every setting that changes a result is in it).
std::string params_json(const JobSpec& spec);

/// Parses what params_json wrote, or a JSON object of the same names with string, number or
/// boolean values. Returns an empty string or a message.
std::string parse_params_json(const std::string& text, JobSpec& spec);

/// The parameters' command-line help: "  --flag VALUE   help (default D)" lines.
std::string params_usage();

/// The parameters as a JSON array of OpenAPI 3 query parameter objects (name, description, and a
/// schema with type, default, minimum and maximum or enum), for the API description and forms.
std::string params_openapi_json();

/// Where a running job is, as its event stream and status report it.
struct JobProgress {
  std::string phase = "shooting";  ///< shooting, linking, gathering, tracing or done
  double fraction = 0.0;           ///< of the phase, 0 to 1 (shooting: by log of unshot power)
  uint64_t shots = 0;
  double unshot_fraction = 1.0;
  uint64_t elements = 0;
  double eta_seconds = -1.0;       ///< -1: unknown
  double elapsed_seconds = 0.0;    ///< since the bake started
  uint64_t links = 0;              ///< hr only
  uint32_t iterations = 0;         ///< hr only
  bool hierarchical = false;       ///< links and iterations are reported
};

/// The progress as a JSON object text.
std::string progress_json(const JobProgress& progress);

/// Reads what progress_json wrote (missing members keep their defaults); nullopt if `text` is not
/// a JSON object.
std::optional<JobProgress> parse_progress_json(const std::string& text);

}  // namespace hemibake::protocol
