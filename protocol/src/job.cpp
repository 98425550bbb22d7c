#include "hemibake/protocol/job.h"

#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

namespace hemibake::protocol {
namespace {

using Kind = ParamInfo::Kind;

// The presets (README, "Quality"); measured on the Cornell box against the path tracer in the
// README's table.
void apply_quality(JobSpec& s, Quality q) {
  const solver::Params defaults = default_solver_params();
  s.quality = q;
  s.params.resolution = defaults.resolution;
  s.params.feps = defaults.feps;
  s.params.beps = defaults.beps;
  s.params.convergence = defaults.convergence;
  s.params.gather = defaults.gather;
  s.params.pools = defaults.pools;
  switch (q) {
    case Quality::kDraft:
      s.params.resolution = 50;
      s.params.feps = 3e-3;
      s.params.beps = 0.1;
      s.params.convergence = 0.01;
      s.params.pools = false;
      break;
    case Quality::kDefault: break;
    case Quality::kHigh:
      s.params.gather = true;
      break;
  }
}

// The table. Limits are the wire's and the command line's alike; what one number cannot bound
// (an even resolution, feps > 0) the solver's validate() checks after.
constexpr double kNoLimit = 1e300;
const ParamInfo kParams[] = {
    {"method", "method", Kind::kMethod, 0, 3,
     "aa (anti-aliased hemicube), classical, hr (hierarchical radiosity) or reference (path-traced)",
     [](const JobSpec& s) { return static_cast<double>(s.method); },
     [](JobSpec& s, double v) { s.method = static_cast<Method>(v); }},
    {"quality", "quality", Kind::kQuality, 0, 2,
     "draft, default or high: a preset of resolution, feps, beps, convergence, pools and gather, which those given with it override",
     [](const JobSpec& s) { return static_cast<double>(s.quality); },
     [](JobSpec& s, double v) { apply_quality(s, static_cast<Quality>(v)); }},
    {"resolution", "resolution", Kind::kWhole, 4, 4096, "hemicube top face in pixels (even)",
     [](const JobSpec& s) { return static_cast<double>(s.params.resolution); },
     [](JobSpec& s, double v) { s.params.resolution = static_cast<uint32_t>(v); }},
    {"feps", "feps", Kind::kNumber, 0, kNoLimit, "form-factor tolerance (splits by form factor)",
     [](const JobSpec& s) { return s.params.feps; }, [](JobSpec& s, double v) { s.params.feps = v; }},
    {"aeps", "aeps", Kind::kNumber, 0, 1, "smallest element area, as a fraction of the scene's area",
     [](const JobSpec& s) { return s.params.aeps; }, [](JobSpec& s, double v) { s.params.aeps = v; }},
    {"beps", "beps", Kind::kNumber, 0, kNoLimit, "radiosity tolerance (splits at jumps across an element)",
     [](const JobSpec& s) { return s.params.beps; }, [](JobSpec& s, double v) { s.params.beps = v; }},
    {"convergence", "convergence", Kind::kNumber, 0, 1, "stop when unshot power is below this fraction of the emitted and each shooter's below ten times this of its own light",
     [](const JobSpec& s) { return s.params.convergence; }, [](JobSpec& s, double v) { s.params.convergence = v; }},
    {"max_shots", "max-shots", Kind::kWhole, 0, static_cast<double>(1ull << 40), "stop after this many shots",
     [](const JobSpec& s) { return static_cast<double>(s.params.max_shots); },
     [](JobSpec& s, double v) { s.params.max_shots = static_cast<uint64_t>(v); }},
    {"max_elements", "max-elements", Kind::kWhole, 1, static_cast<double>(1ull << 32), "no splits past this many elements",
     [](const JobSpec& s) { return static_cast<double>(s.params.max_elements); },
     [](JobSpec& s, double v) { s.params.max_elements = static_cast<uint64_t>(v); }},
    {"threads", "threads", Kind::kWhole, 0, 1024, "threads (0: all cores; a server sets its own)",
     [](const JobSpec& s) { return static_cast<double>(s.params.threads); },
     [](JobSpec& s, double v) { s.params.threads = static_cast<uint32_t>(v); }},
    {"reuse", "reuse", Kind::kFlag, 0, 1, "children take visibility from their parent's pixels (off: re-project the scene)",
     [](const JobSpec& s) { return s.params.reuse_visibility ? 1.0 : 0.0; },
     [](JobSpec& s, double v) { s.params.reuse_visibility = v != 0.0; }},
    {"gather", "gather", Kind::kFlag, 0, 1,
     "aa, classical: after the shots every vertex gathers the light it sees, and faces split where it is not linear (off: vertices average their elements; see README)",
     [](const JobSpec& s) { return s.params.gather ? 1.0 : 0.0; },
     [](JobSpec& s, double v) { s.params.gather = v != 0.0; }},
    {"pools", "pools", Kind::kFlag, 0, 1,
     "aa, classical: a quick first pass finds where light pools on surfaces too large for one shot to split (a floor under small lamps, a window's light, the ceiling over them), and the solve starts with them split (off: one pass, as at the draft preset; see README)",
     [](const JobSpec& s) { return s.params.pools ? 1.0 : 0.0; },
     [](JobSpec& s, double v) { s.params.pools = v != 0.0; }},
    {"sharp_shadows", "sharp-shadows", Kind::kFlag, 0, 1,
     "aa: pieces shooting at least 1 % of the light use twice the hemicube resolution (at most 400) at every near-field level: every small object close to a large emitter casts its shadow (off: each level halves the resolution, as far as the objects a piece may see stay two pixels wide; see README)",
     [](const JobSpec& s) { return s.params.sharp_shadows ? 1.0 : 0.0; },
     [](JobSpec& s, double v) { s.params.sharp_shadows = v != 0.0; }},
    {"cluster_size", "cluster-size", Kind::kNumber, 0, kNoLimit,
     "small patches shoot together in clusters up to this times the scene's diagonal wide (0: alone)",
     [](const JobSpec& s) { return s.params.cluster_size; }, [](JobSpec& s, double v) { s.params.cluster_size = v; }},
    {"cluster_across", "cluster-across", Kind::kFlag, 0, 1,
     "faces of small objects cluster with nearby faces of other objects (off: only within a surface)",
     [](const JobSpec& s) { return s.params.cluster_across ? 1.0 : 0.0; },
     [](JobSpec& s, double v) { s.params.cluster_across = v != 0.0; }},
    {"cluster_volume", "cluster-volume", Kind::kFlag, 0, 1,
     "those faces cluster whatever way they face, and a cluster facing several ways shoots from one whole cube at its centre (off: one cluster per orientation class)",
     [](const JobSpec& s) { return s.params.cluster_volume ? 1.0 : 0.0; },
     [](JobSpec& s, double v) { s.params.cluster_volume = v != 0.0; }},
    {"shot_cache_mb", "shot-cache-mb", Kind::kWhole, 0, 1 << 20, "memory for replaying a shooter's earlier form factors (0: off)",
     [](const JobSpec& s) { return static_cast<double>(s.params.shot_cache_mb); },
     [](JobSpec& s, double v) { s.params.shot_cache_mb = static_cast<uint32_t>(v); }},
    {"rays", "rays", Kind::kWhole, 1, 1024, "hr: visibility rays per link",
     [](const JobSpec& s) { return static_cast<double>(s.rays); },
     [](JobSpec& s, double v) { s.rays = static_cast<uint32_t>(v); }},
    {"samples", "samples", Kind::kWhole, 1, 1 << 20, "reference: paths per vertex",
     [](const JobSpec& s) { return static_cast<double>(s.samples); },
     [](JobSpec& s, double v) { s.samples = static_cast<uint32_t>(v); }},
    {"draco", "draco", Kind::kFlag, 0, 1, "KHR_draco_mesh_compression (off: plain accessors)",
     [](const JobSpec& s) { return s.write.draco ? 1.0 : 0.0; }, [](JobSpec& s, double v) { s.write.draco = v != 0.0; }},
    {"position_bits", "position-bits", Kind::kWhole, 0, 30, "Draco position quantization (0: lossless)",
     [](const JobSpec& s) { return static_cast<double>(s.write.position_bits); },
     [](JobSpec& s, double v) { s.write.position_bits = static_cast<int>(v); }},
    {"texcoord_bits", "texcoord-bits", Kind::kWhole, 0, 30, "Draco texture coordinate quantization (0: lossless)",
     [](const JobSpec& s) { return static_cast<double>(s.write.texcoord_bits); },
     [](JobSpec& s, double v) { s.write.texcoord_bits = static_cast<int>(v); }},
    {"draco_speed", "draco-speed", Kind::kWhole, 0, 10, "Draco encode and decode speed (0: smallest file, 10: fastest)",
     [](const JobSpec& s) { return static_cast<double>(s.write.encode_speed); },
     [](JobSpec& s, double v) { s.write.encode_speed = s.write.decode_speed = static_cast<int>(v); }},
    {"exposure", "exposure", Kind::kNumber, 0, kNoLimit, "radiosity scale for COLOR_0 below the knee (0: chosen from the scene)",
     [](const JobSpec& s) { return s.write.exposure; }, [](JobSpec& s, double v) { s.write.exposure = v; }},
    {"tone", "tone", Kind::kTone, 0, 1,
     "COLOR_0's highlights: shoulder (exposure x light below a knee, then rolled off to reach 1 at the brightest lit surface, hue kept) or clamp (exposure x light, each channel clipped at 1)",
     [](const JobSpec& s) { return static_cast<double>(s.write.tone); },
     [](JobSpec& s, double v) { s.write.tone = static_cast<Tone>(v); }},
    {"shooter_size", "shooter-size", Kind::kNumber, 0, kNoLimit,
     "a patch shoots from sub-areas no wider than this times the scene's diagonal",
     [](const JobSpec& s) { return s.params.shooter_size; }, [](JobSpec& s, double v) { s.params.shooter_size = v; }},
    {"color_bits", "color-bits", Kind::kWhole, 0, 30, "Draco colour quantization (0: lossless)",
     [](const JobSpec& s) { return static_cast<double>(s.write.color_bits); },
     [](JobSpec& s, double v) { s.write.color_bits = static_cast<int>(v); }},
    {"sky", "sky", Kind::kColour, 0, kNoLimit,
     "radiance of a uniform sky around the scene, R,G,B (or one number for grey; aa, classical and reference)",
     [](const JobSpec& s) { return (s.sky.x + s.sky.y + s.sky.z) / 3.0; },
     [](JobSpec& s, double v) { s.sky = glm::dvec3(v); },
     [](const JobSpec& s) { return s.sky; }, [](JobSpec& s, const glm::dvec3& v) { s.sky = v; }},
};

bool number(const std::string& text, double& out) {
  char* end = nullptr;
  out = std::strtod(text.c_str(), &end);
  return !text.empty() && end == text.c_str() + text.size() && std::isfinite(out);
}

bool flag(const std::string& text, double& out) {
  if (text == "true" || text == "1" || text == "yes") return out = 1.0, true;
  if (text == "false" || text == "0" || text == "no") return out = 0.0, true;
  return false;
}

std::string shortest(double x) {
  char buf[64];
  if (x == std::floor(x) && std::abs(x) < 1e15) {
    std::snprintf(buf, sizeof buf, "%.0f", x);
    return buf;
  }
  std::snprintf(buf, sizeof buf, "%.17g", x);
  for (int digits = 1; digits < 17; ++digits) {
    char shorter[64];
    std::snprintf(shorter, sizeof shorter, "%.*g", digits, x);
    if (std::strtod(shorter, nullptr) == x) return shorter;
  }
  return buf;
}

}  // namespace

const char* to_string(Quality quality) {
  switch (quality) {
    case Quality::kDraft: return "draft";
    case Quality::kDefault: return "default";
    case Quality::kHigh: return "high";
  }
  return "default";
}

std::optional<Quality> quality_from(std::string_view name) {
  for (Quality q : {Quality::kDraft, Quality::kDefault, Quality::kHigh})
    if (name == to_string(q)) return q;
  return std::nullopt;
}

const char* to_string(Method method) {
  switch (method) {
    case Method::kAntiAliased: return "aa";
    case Method::kClassical: return "classical";
    case Method::kHierarchical: return "hr";
    case Method::kReference: return "reference";
  }
  return "aa";
}

std::optional<Method> method_from(std::string_view name) {
  for (Method m : {Method::kAntiAliased, Method::kClassical, Method::kHierarchical, Method::kReference})
    if (name == to_string(m)) return m;
  return std::nullopt;
}

solver::Params solver_params(const JobSpec& spec) {
  solver::Params p = spec.params;
  p.method = spec.method == Method::kClassical ? solver::Method::kClassical : solver::Method::kAntiAliased;
  return p;
}

std::span<const ParamInfo> param_table() { return kParams; }

std::string parse_colour_value(const ParamInfo& p, const std::string& text, glm::dvec3& value) {
  std::vector<std::string> parts;
  size_t start = 0;
  while (true) {
    const size_t comma = text.find(',', start);
    parts.push_back(text.substr(start, comma == std::string::npos ? std::string::npos : comma - start));
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  const std::string wanted = "must be R,G,B or one number, each from " + shortest(p.min) +
                             (p.max >= kNoLimit ? std::string(" up") : " to " + shortest(p.max)) + " (got '" + text + "')";
  if (parts.size() != 1 && parts.size() != 3) return wanted;
  for (size_t c = 0; c < 3; ++c) {
    double v = 0.0;
    if (!number(parts[parts.size() == 1 ? 0 : c], v) || v < p.min || v > p.max) return wanted;
    value[static_cast<int>(c)] = v;
  }
  return "";
}

std::string parse_param_value(const ParamInfo& p, const std::string& text, double& value) {
  const std::string got = " (got '" + text + "')";
  switch (p.kind) {
    case Kind::kColour: {
      glm::dvec3 c(0.0);
      if (std::string e = parse_colour_value(p, text, c); !e.empty()) return e;
      value = (c.x + c.y + c.z) / 3.0;
      return "";
    }
    case Kind::kMethod:
      if (const auto m = method_from(text)) return value = static_cast<double>(*m), "";
      return "must be aa, classical, hr or reference" + got;
    case Kind::kQuality:
      if (const auto q = quality_from(text)) return value = static_cast<double>(*q), "";
      return "must be draft, default or high" + got;
    case Kind::kTone:
      if (const auto t = tone_from(text)) return value = static_cast<double>(*t), "";
      return "must be shoulder or clamp" + got;
    case Kind::kFlag:
      if (flag(text, value)) return "";
      return "must be true or false" + got;
    case Kind::kWhole:
      if (number(text, value) && value == std::floor(value) && value >= p.min && value <= p.max) return "";
      return "must be a whole number from " + shortest(p.min) + " to " + shortest(p.max) + got;
    case Kind::kNumber:
      if (number(text, value) && value >= p.min && value <= p.max) return "";
      if (p.max >= kNoLimit) return "must be a number from " + shortest(p.min) + " up" + got;
      return "must be a number from " + shortest(p.min) + " to " + shortest(p.max) + got;
  }
  return "is not understood" + got;
}

const ParamInfo* find_param(std::string_view name) {
  for (const ParamInfo& p : kParams)
    if (name == p.name) return &p;
  return nullptr;
}

std::string apply_params(const std::map<std::string, std::string>& values, JobSpec& spec) {
  // The preset first: the parameters given with it override it, whatever their order.
  if (const auto q = values.find("quality"); q != values.end()) {
    double v = 0.0;
    if (std::string e = parse_param_value(*find_param("quality"), q->second, v); !e.empty()) return "quality " + e;
    apply_quality(spec, static_cast<Quality>(v));
  }
  for (const auto& [key, value] : values) {
    if (key == "quality") continue;
    const ParamInfo* p = find_param(key);
    if (p == nullptr) return "unknown parameter '" + key + "'";
    if (p->kind == Kind::kColour) {
      glm::dvec3 c(0.0);
      if (std::string e = parse_colour_value(*p, value, c); !e.empty()) return key + " " + e;
      p->set_colour(spec, c);
      continue;
    }
    double v = 0.0;
    if (std::string e = parse_param_value(*p, value, v); !e.empty()) return key + " " + e;
    p->set(spec, v);
  }
  return solver::validate(solver_params(spec));
}

std::string params_json(const JobSpec& spec) {
  nlohmann::ordered_json j;
  for (const ParamInfo& p : kParams) {
    const double v = p.get(spec);
    switch (p.kind) {
      case Kind::kMethod: j[p.name] = to_string(static_cast<Method>(v)); break;
      case Kind::kQuality: j[p.name] = to_string(static_cast<Quality>(v)); break;
      case Kind::kTone: j[p.name] = to_string(static_cast<Tone>(v)); break;
      case Kind::kFlag: j[p.name] = v != 0.0; break;
      case Kind::kWhole: j[p.name] = static_cast<uint64_t>(v); break;
      case Kind::kNumber: j[p.name] = v; break;
      case Kind::kColour: {
        const glm::dvec3 c = p.get_colour(spec);
        j[p.name] = shortest(c.x) + "," + shortest(c.y) + "," + shortest(c.z);
        break;
      }
    }
  }
  return j.dump();
}

std::string parse_params_json(const std::string& text, JobSpec& spec) {
  const nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
  if (j.is_discarded() || !j.is_object()) return "params must be a JSON object";
  std::map<std::string, std::string> values;
  for (const auto& [key, v] : j.items()) {
    if (v.is_string()) values[key] = v.get<std::string>();
    else if (v.is_boolean()) values[key] = v.get<bool>() ? "true" : "false";
    else if (v.is_number_unsigned()) values[key] = std::to_string(v.get<uint64_t>());
    else if (v.is_number_integer()) values[key] = std::to_string(v.get<int64_t>());
    else if (v.is_number()) {
      char buf[64];
      std::snprintf(buf, sizeof buf, "%.17g", v.get<double>());
      values[key] = buf;
    } else if (v.is_array() && v.size() == 3 && v[0].is_number() && v[1].is_number() && v[2].is_number()) {
      // A colour as [r, g, b].
      values[key] = shortest(v[0].get<double>()) + "," + shortest(v[1].get<double>()) + "," + shortest(v[2].get<double>());
    } else return "params." + key + " must be a string, number, boolean or [r, g, b]";
  }
  return apply_params(values, spec);
}

std::string params_usage() {
  const JobSpec defaults;
  std::string out;
  for (const ParamInfo& p : kParams) {
    const double v = p.get(defaults);
    std::string head = "  --";
    if (p.kind == Kind::kFlag) head += (v != 0.0 ? std::string("no-") : std::string()) + p.flag;
    else head += std::string(p.flag) + (p.kind == Kind::kMethod ? " M" : p.kind == Kind::kQuality ? " Q" : p.kind == Kind::kTone ? " T" : p.kind == Kind::kWhole ? " N" : p.kind == Kind::kColour ? " R,G,B" : " X");
    if (head.size() < 26) head.resize(26, ' ');
    else head += ' ';
    std::string def;
    switch (p.kind) {
      case Kind::kMethod: def = to_string(static_cast<Method>(v)); break;
      case Kind::kQuality: def = to_string(static_cast<Quality>(v)); break;
      case Kind::kTone: def = to_string(static_cast<Tone>(v)); break;
      case Kind::kFlag: def = v != 0.0 ? "on" : "off"; break;
      case Kind::kColour: {
        const glm::dvec3 c = p.get_colour(defaults);
        def = shortest(c.x) + "," + shortest(c.y) + "," + shortest(c.z);
        break;
      }
      default: def = shortest(v); break;
    }
    out += head + p.help + " (default " + def + ")\n";
  }
  return out;
}

std::string params_openapi_json() {
  const JobSpec defaults;
  nlohmann::ordered_json list = nlohmann::ordered_json::array();
  for (const ParamInfo& p : kParams) {
    const double v = p.get(defaults);
    nlohmann::ordered_json schema;
    switch (p.kind) {
      case Kind::kMethod:
        schema["type"] = "string";
        schema["enum"] = {"aa", "classical", "hr", "reference"};
        schema["default"] = to_string(static_cast<Method>(v));
        break;
      case Kind::kQuality:
        schema["type"] = "string";
        schema["enum"] = {"draft", "default", "high"};
        schema["default"] = to_string(static_cast<Quality>(v));
        break;
      case Kind::kTone:
        schema["type"] = "string";
        schema["enum"] = {"shoulder", "clamp"};
        schema["default"] = to_string(static_cast<Tone>(v));
        break;
      case Kind::kFlag:
        schema["type"] = "boolean";
        schema["default"] = v != 0.0;
        break;
      case Kind::kWhole:
        schema["type"] = "integer";
        schema["default"] = static_cast<uint64_t>(v);
        schema["minimum"] = static_cast<uint64_t>(p.min);
        schema["maximum"] = static_cast<uint64_t>(p.max);
        break;
      case Kind::kNumber:
        schema["type"] = "number";
        schema["default"] = v;
        schema["minimum"] = p.min;
        if (p.max < kNoLimit) schema["maximum"] = p.max;
        break;
      case Kind::kColour: {
        // "R,G,B" or one number; JSON bodies may also give [r, g, b].
        const glm::dvec3 c = p.get_colour(defaults);
        schema["type"] = "string";
        schema["pattern"] = "^[^,]+(,[^,]+,[^,]+)?$";
        schema["default"] = shortest(c.x) + "," + shortest(c.y) + "," + shortest(c.z);
        break;
      }
    }
    list.push_back({{"name", p.name}, {"in", "query"}, {"required", false}, {"description", p.help}, {"schema", schema}});
  }
  return list.dump();
}

std::string progress_json(const JobProgress& p) {
  nlohmann::json j = {{"phase", p.phase},         {"fraction", p.fraction},       {"shots", p.shots},
                      {"unshot_fraction", p.unshot_fraction}, {"elements", p.elements}, {"eta_seconds", p.eta_seconds},
                      {"elapsed_seconds", p.elapsed_seconds}};
  if (p.hierarchical) {
    j["links"] = p.links;
    j["iterations"] = p.iterations;
  }
  return j.dump();
}

std::optional<JobProgress> parse_progress_json(const std::string& text) {
  const nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
  if (j.is_discarded() || !j.is_object()) return std::nullopt;
  JobProgress p;
  // value() throws on a member of another type; a stream from another version is shown, not fatal.
  auto read = [&](const char* key, auto& out) {
    const auto it = j.find(key);
    if (it == j.end()) return;
    if constexpr (std::is_same_v<std::decay_t<decltype(out)>, std::string>) {
      if (it->is_string()) out = it->template get<std::string>();
    } else {
      if (it->is_number()) out = it->template get<std::decay_t<decltype(out)>>();
    }
  };
  read("phase", p.phase);
  read("fraction", p.fraction);
  read("shots", p.shots);
  read("unshot_fraction", p.unshot_fraction);
  read("elements", p.elements);
  read("eta_seconds", p.eta_seconds);
  read("elapsed_seconds", p.elapsed_seconds);
  read("links", p.links);
  read("iterations", p.iterations);
  p.hierarchical = j.contains("links");
  return p;
}

}  // namespace hemibake::protocol
