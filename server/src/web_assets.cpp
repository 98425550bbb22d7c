#include "web_assets.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cctype>

namespace hemibake::server::web {
namespace {

// The path in the message comes from the request: bytes that are not UTF-8 are replaced, not thrown.
Response plain_error(int status, const std::string& message) {
  Response r;
  r.status = status;
  r.body = nlohmann::json{{"error", message}}.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  return r;
}

// Whether a header's comma-separated list (Accept-Encoding, If-None-Match) has `token`, ignoring
// case for encodings and parameters after ';'. q=0 refuses a coding (RFC 9110, section 12.5.3).
bool lists(const std::string& value, const std::string& token, bool ignore_case) {
  size_t start = 0;
  while (start <= value.size()) {
    size_t end = value.find(',', start);
    if (end == std::string::npos) end = value.size();
    std::string item = value.substr(start, end - start);
    std::string params;
    if (const size_t semi = item.find(';'); semi != std::string::npos) {
      params = item.substr(semi + 1);
      item.resize(semi);
    }
    const auto blank = [](unsigned char c) { return std::isspace(c) != 0; };
    item.erase(item.begin(), std::find_if_not(item.begin(), item.end(), blank));
    item.erase(std::find_if_not(item.rbegin(), item.rend(), blank).base(), item.end());
    params.erase(std::remove_if(params.begin(), params.end(), blank), params.end());
    if (ignore_case) std::transform(item.begin(), item.end(), item.begin(), [](unsigned char c) { return std::tolower(c); });
    const bool refused = params == "q=0" || params == "q=0.0" || params == "q=0.00" || params == "q=0.000";
    if ((item == token || item == "*") && !refused) return true;
    start = end + 1;
  }
  return false;
}

std::string header(const Request& request, const char* name) {
  const auto it = request.headers.find(name);
  return it == request.headers.end() ? std::string() : it->second;
}

}  // namespace

std::optional<Response> answer(const Request& request, const std::string& path) {
  const bool page = path == "/" || path == "/index.html";
  if (!page && path.rfind("/assets/", 0) != 0) return std::nullopt;
  const std::string wanted = page ? "/" : path;
  const Asset* asset = nullptr;
  for (size_t i = 0; i < kAssetCount; ++i)
    if (wanted == kAssets[i].path) asset = &kAssets[i];
  if (request.method != "GET") {
    Response r = plain_error(405, "use GET or HEAD here");
    r.headers.emplace_back("Allow", "GET, HEAD");
    return r;
  }
  if (!asset) return plain_error(404, "no such file: " + path);

  const bool gzip = !asset->gzip.empty() && lists(header(request, "accept-encoding"), "gzip", true);
  // The two encodings are two representations, so they have two validators.
  std::string etag = asset->etag;
  if (gzip) etag.insert(etag.size() - 1, "-gz");
  Response r;
  // Revalidated on every use (a cheap 304): a new build of the server serves a new page at once.
  r.headers.emplace_back("Cache-Control", "no-cache");
  r.headers.emplace_back("ETag", etag);
  r.headers.emplace_back("X-Content-Type-Options", "nosniff");
  if (!asset->gzip.empty()) r.headers.emplace_back("Vary", "Accept-Encoding");
  if (page) {
    r.headers.emplace_back("Content-Security-Policy", kContentSecurityPolicy);
    r.headers.emplace_back("Referrer-Policy", "no-referrer");
  }
  if (lists(header(request, "if-none-match"), etag, false)) {
    r.status = 304;
    r.content_type.clear();
    return r;
  }
  r.content_type = asset->content_type;
  if (gzip) r.headers.emplace_back("Content-Encoding", "gzip");
  const std::string_view body = gzip ? asset->gzip : asset->body;
  r.body.assign(body.data(), body.size());
  return r;
}

}  // namespace hemibake::server::web
