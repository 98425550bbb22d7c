// The `hemibake` commands that talk to a hemibake-server.
#pragma once

#include "hemibake/protocol/job.h"

#include <map>
#include <string>

namespace hemibake::client {

struct Remote {
  std::string host;
  std::string port;
  std::string token;  ///< bearer token, or empty
};

/// Parses http://HOST[:PORT][/] into `out`; returns an error message or an empty string.
std::string parse_server(const std::string& url, Remote& out);

/// hemibake submit: prints the job id; returns the exit status.
int remote_submit(const Remote& r, const std::string& path, const protocol::JobSpec& spec, std::string* id_out = nullptr);
int remote_status(const Remote& r, const std::string& id);
/// Follows the job's event stream with a progress line; 0 if it succeeded.
int remote_watch(const Remote& r, const std::string& id);
int remote_fetch(const Remote& r, const std::string& id, const std::string& out_path);
int remote_cancel(const Remote& r, const std::string& id);
int remote_list(const Remote& r, const std::string& state);
/// submit + watch + fetch.
int remote_bake(const Remote& r, const std::string& in, const std::string& out, const protocol::JobSpec& spec);

}  // namespace hemibake::client
