// One request to a hemibake-server, tried again while the server asks to be asked later or the
// connection fails in a way a retry can mend. Internal to the client: the commands in remote.cpp
// are made of it, and its tests call it without a command.
#pragma once

#include "hemibake/client/console.h"
#include "hemibake/client/remote.h"

#include <map>
#include <string>

namespace hemibake::client {

/// How a request that got no answer failed.
enum class Failure {
  kNone,     ///< it was answered
  kRefused,  ///< nothing listens at the address (connection refused): the request was not sent
  kCut,      ///< the connection was reset or closed before a whole answer: the request may have
             ///< reached the server, and the server may have acted on it
  kOther,    ///< anything else (a name that does not resolve, a timeout)
};

/// What a request came to: an answer, or a failure.
struct Reply {
  int status = 0;  ///< the HTTP status; 0 without an answer
  std::string body;
  std::map<std::string, std::string> headers;
  Failure failure = Failure::kNone;
  std::string error;            ///< without an answer: what happened, for the user
  double retry_after = -1.0;    ///< seconds, from Retry-After (delay-seconds); -1: none
  double gave_up_after = -1.0;  ///< still failing as above after this many seconds of retries
  bool earlier_try_cut = false; ///< an earlier try was cut after it was sent (it may have acted)
};

/// Sends `method target` with `body` (of `content_type`, if not empty) and `headers`, and reads the
/// answer. While the server answers 503 or 429 it is asked again as Retry-After says (5 s without
/// one); a refused connection, and a cut one if the request may be repeated (GET, HEAD, PUT,
/// DELETE, OPTIONS, or any with an Idempotency-Key header), are tried again after 0.5 s, doubling
/// up to 5 s. All of this for up to r.retry_seconds from the first failure, saying on c.err what it
/// waits for (`what` names the action: "listing jobs"). Returns the last answer or failure; a cut
/// request that may not be repeated says so in its error.
Reply call_retrying(const Remote& r, const Console& c, const std::string& what, const std::string& method,
                    const std::string& target, const std::string& body = {}, const std::string& content_type = {},
                    const std::map<std::string, std::string>& headers = {});

}  // namespace hemibake::client
