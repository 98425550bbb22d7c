// The web page hemibake-server serves at / and its files under /assets/ (the page's sources from
// web/src and the three.js files it imports), embedded at build time by web/embed.mjs. They are
// answered without a token: the page itself holds nothing secret and asks for the token that its
// API requests need.
#pragma once

#include "hemibake/server/service.h"

#include <cstddef>
#include <optional>
#include <string>
#include <string_view>

namespace hemibake::server::web {

/// One embedded file. `gzip` is empty when compressing did not pay.
struct Asset {
  const char* path;          ///< URL path: "/" or "/assets/..."
  const char* content_type;
  std::string_view body;
  std::string_view gzip;
  const char* etag;          ///< quoted, as sent in ETag
};

// Generated (web_assets_data.cpp).
extern const Asset kAssets[];
extern const size_t kAssetCount;
extern const char* const kThreeVersion;
extern const char* const kContentSecurityPolicy;

/// The answer for `path` if it is the page's (/, /index.html, anything under /assets/), else
/// nullopt: 200 with the file (gzip when the request accepts it), 304 for a matching
/// If-None-Match, 404 for an unknown file under /assets/, 405 for methods other than GET (HEAD
/// arrives as GET). `request.method` and its headers are read; the body is not.
std::optional<Response> answer(const Request& request, const std::string& path);

}  // namespace hemibake::server::web
