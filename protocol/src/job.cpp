#include "hemibake/protocol/job.h"

#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdlib>

namespace hemibake::protocol {
namespace {

bool number(const std::string& text, double& out) {
  char* end = nullptr;
  out = std::strtod(text.c_str(), &end);
  return !text.empty() && end == text.c_str() + text.size() && std::isfinite(out);
}

bool whole(const std::string& text, uint64_t max, uint64_t& out) {
  double x;
  if (!number(text, x) || x < 0 || x > static_cast<double>(max) || x != std::floor(x)) return false;
  out = static_cast<uint64_t>(x);
  return true;
}

bool flag(const std::string& text, bool& out) {
  if (text == "true" || text == "1" || text == "yes") return out = true, true;
  if (text == "false" || text == "0" || text == "no") return out = false, true;
  return false;
}

}  // namespace

std::string apply_params(const std::map<std::string, std::string>& values, JobSpec& spec) {
  solver::Params& p = spec.params;
  WriteOptions& w = spec.write;
  for (const auto& [key, value] : values) {
    double x = 0.0;
    uint64_t n = 0;
    bool b = false;
    bool ok = true;
    if (key == "method") {
      // hr and reference keep params.method: reference bakes the aa (or classical) mesh first.
      if (value == "aa" || value == "classical") {
        p.method = value == "aa" ? solver::Method::kAntiAliased : solver::Method::kClassical;
        w.method.clear();
      } else if (value == "hr" || value == "reference") {
        p.method = solver::Method::kAntiAliased;
        w.method = value;
      } else {
        return "method must be aa, classical, hr or reference (got '" + value + "')";
      }
    } else if (key == "resolution") {
      ok = whole(value, 4096, n);
      p.resolution = static_cast<uint32_t>(n);
    } else if (key == "feps") {
      ok = number(value, p.feps);
    } else if (key == "aeps") {
      ok = number(value, p.aeps);
    } else if (key == "beps") {
      ok = number(value, p.beps);
    } else if (key == "convergence") {
      ok = number(value, p.convergence);
    } else if (key == "max_shots") {
      ok = whole(value, 1ull << 40, n);
      p.max_shots = n;
    } else if (key == "max_elements") {
      ok = whole(value, 1ull << 32, n);
      p.max_elements = n;
    } else if (key == "threads") {
      ok = whole(value, 1024, n);
      p.threads = static_cast<uint32_t>(n);
    } else if (key == "reuse") {
      ok = flag(value, b);
      p.reuse_visibility = b;
    } else if (key == "cluster_size") {
      ok = number(value, p.cluster_size);
    } else if (key == "shot_cache_mb") {
      ok = whole(value, 1u << 20, n);
      p.shot_cache_mb = static_cast<uint32_t>(n);
    } else if (key == "rays") {
      ok = whole(value, 1024, n) && n >= 1;
      spec.rays = static_cast<uint32_t>(n);
    } else if (key == "samples") {
      ok = whole(value, 1u << 20, n) && n >= 1;
      spec.samples = static_cast<uint32_t>(n);
    } else if (key == "draco") {
      ok = flag(value, b);
      w.draco = b;
    } else if (key == "position_bits") {
      ok = whole(value, 30, n);
      w.position_bits = static_cast<int>(n);
    } else if (key == "texcoord_bits") {
      ok = whole(value, 30, n);
      w.texcoord_bits = static_cast<int>(n);
    } else if (key == "draco_speed") {
      ok = whole(value, 10, n);
      w.encode_speed = w.decode_speed = static_cast<int>(n);
    } else if (key == "exposure") {
      ok = number(value, x) && x >= 0.0;
      w.exposure = x;
    } else {
      return "unknown parameter '" + key + "'";
    }
    if (!ok) return "parameter " + key + " has a bad value '" + value + "'";
  }
  return solver::validate(p);
}

std::string params_json(const JobSpec& spec) {
  const solver::Params& p = spec.params;
  const WriteOptions& w = spec.write;
  nlohmann::ordered_json j;
  j["method"] = !w.method.empty() ? w.method : p.method == solver::Method::kAntiAliased ? "aa" : "classical";
  j["resolution"] = p.resolution;
  j["feps"] = p.feps;
  j["aeps"] = p.aeps;
  j["beps"] = p.beps;
  j["convergence"] = p.convergence;
  j["max_shots"] = p.max_shots;
  j["max_elements"] = p.max_elements;
  j["threads"] = p.threads;
  j["reuse"] = p.reuse_visibility;
  j["cluster_size"] = p.cluster_size;
  j["shot_cache_mb"] = p.shot_cache_mb;
  j["rays"] = spec.rays;
  j["samples"] = spec.samples;
  j["draco"] = w.draco;
  j["position_bits"] = w.position_bits;
  j["texcoord_bits"] = w.texcoord_bits;
  j["draco_speed"] = w.encode_speed;
  j["exposure"] = w.exposure;
  return j.dump();
}

std::string parse_params_json(const std::string& text, JobSpec& spec) {
  const nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
  if (j.is_discarded() || !j.is_object()) return "params must be a JSON object";
  std::map<std::string, std::string> values;
  for (const auto& [key, v] : j.items()) {
    if (v.is_string()) values[key] = v.get<std::string>();
    else if (v.is_boolean()) values[key] = v.get<bool>() ? "true" : "false";
    else if (v.is_number_integer() || v.is_number_unsigned()) values[key] = std::to_string(v.get<int64_t>());
    else if (v.is_number()) {
      char buf[64];
      std::snprintf(buf, sizeof buf, "%.17g", v.get<double>());
      values[key] = buf;
    } else return "params." + key + " must be a string, number or boolean";
  }
  return apply_params(values, spec);
}

}  // namespace hemibake::protocol
