// libFuzzer target: the job parameter parsers. The input is a query string, a newline, and a JSON
// parameter object. Whatever the query parser accepts must survive params_json and
// parse_params_json unchanged (the cache key and the worker depend on that round trip).
#include "hemibake/protocol/job.h"
#include "hemibake/server/service.h"

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string input(reinterpret_cast<const char*>(data), size);
  const size_t newline = input.find('\n');
  const std::string query = input.substr(0, newline);
  hemibake::protocol::JobSpec spec;
  if (hemibake::protocol::apply_params(hemibake::server::parse_query(query), spec).empty()) {
    const std::string text = hemibake::protocol::params_json(spec);
    hemibake::protocol::JobSpec again;
    const std::string e = hemibake::protocol::parse_params_json(text, again);
    if (!e.empty() || hemibake::protocol::params_json(again) != text) {
      std::fprintf(stderr, "round trip failed for %s: %s\n", text.c_str(), e.c_str());
      std::abort();
    }
  }
  if (newline != std::string::npos) {
    hemibake::protocol::JobSpec from_json;
    (void)hemibake::protocol::parse_params_json(input.substr(newline + 1), from_json);
  }
  return 0;
}
