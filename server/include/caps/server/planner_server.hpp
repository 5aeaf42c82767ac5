#pragma once
/// @brief The planner's HTTP server: the page's static files and a JSON API over the app::
/// requests and results (docs/planner.md). Every refusal is a 4xx whose body is
/// {"error": <the message the command line prints>}; the server keeps serving after it.

#include <cstddef>
#include <exception>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "caps/core/reporter.hpp"

namespace caps::server {

/// The largest request body accepted, in bytes (1 MiB; a plan file is a few kB). Larger: 413.
constexpr std::size_t kMaxBodyBytes = std::size_t{1} << 20;
/// The address the server binds unless told otherwise: loopback only.
constexpr const char* kDefaultHost = "127.0.0.1";
/// The port `caps serve` listens on unless told otherwise.
constexpr int kDefaultPort = 8765;
/// Simulations run at once; a newer simulate request (or DELETE /api/simulate, or the server's
/// stop) cancels the one running, which is answered 409.
constexpr int kMaxConcurrentSimulations = 1;
/// Connections served at once; more are answered 503 at once.
constexpr int kMaxConnections = 256;
/// The header of the page's session token (PlannerServer::token()).
constexpr const char* kTokenHeader = "X-Caps-Token";

/// The server's options. The limits protect it from a client that is slow or hostile
/// (docs/reliability.md, "The local planner server").
struct ServerOptions {
  std::string model_dir;            ///< the patient model every request works on
  std::string host = kDefaultHost;  ///< the address to bind (another than loopback: a warning)
  /// Other names requests may carry in their Host (with the port): the name or address by which
  /// other machines reach a server bound to another address than loopback. Host names and IPv4
  /// addresses only (letters, digits, '.', '-'); the bound address and the loopback names are
  /// always allowed.
  std::vector<std::string> allowed_hosts;
  int port = kDefaultPort;          ///< 0: any free port (see PlannerServer::port())
  std::string web_root;             ///< the page's folder; empty: default_web_root()
  std::size_t max_body_bytes = kMaxBodyBytes;
  /// A request's line and headers must all arrive within this time (s) of its first byte.
  double header_timeout_s = 10;
  /// A body (and an answer) may take 10 s plus one second per this many bytes.
  double min_bytes_per_s = 16 * 1024;
  int max_connections = kMaxConnections;  ///< served at once; more: 503
};

/// An error as the server answers it: its HTTP status and the message of the body.
struct ErrorResponse {
  int status = 500;
  std::string message;  ///< the message the command line prints for the same error
};

/// The status an error is answered with: InvalidInput (InvalidParameter) and IoError 400,
/// Cancelled 409 (a newer simulate request, DELETE /api/simulate or the server's stop), SolverError
/// 422, any other error 500.
ErrorResponse error_response(const std::exception& error);

/// True for the loopback addresses (127.0.0.0/8, ::1, localhost): reachable from this machine only.
bool is_loopback(const std::string& host);

/// The web folder served when none is given: the first with an index.html of the page the build
/// bundled beside the program (<program's folder>/../web/dist: build/web/dist for build/tools/caps
/// and for build/tests/*), the build tree's web/dist, the source tree's web/dist; else the
/// source tree's web/ (where only the placeholder index.html is served).
std::filesystem::path default_web_root();

/// The planner's server: owns its routes, its per-server work folder (plans and results under
/// the temporary directory, removed with the server) and the running simulation.
class PlannerServer {
 public:
  /// Loads the model once to check it (the CLI's IoError/InvalidInput otherwise) and creates the
  /// work folder. `reporter` (not owned; may be null; must outlive the server) gets warnings,
  /// notes and the running simulation's progress.
  PlannerServer(ServerOptions options, Reporter* reporter = nullptr);
  ~PlannerServer();
  PlannerServer(const PlannerServer&) = delete;
  PlannerServer& operator=(const PlannerServer&) = delete;

  /// Binds the address and port (IoError if it cannot); warns when the address is not loopback.
  /// @return the port bound (the free one chosen when options.port is 0)
  int bind();
  /// Serves requests until stop() (call bind() first). Blocks.
  void listen();
  /// Stops listen() (from any thread): a running simulation is cancelled (within a second),
  /// other requests under way are finished, idle and slow connections are closed.
  void stop();

  /// The port bound, 0 before bind().
  int port() const;
  /// http://HOST:PORT/
  std::string url() const;
  /// The per-server work folder (plans/, results/<id>/).
  const std::filesystem::path& work_dir() const;
  /// The folder whose files are served at /.
  const std::filesystem::path& web_root() const;
  /// Requests answered so far.
  long n_requests() const;
  /// The session's token: every /api/ request carries it in the X-Caps-Token header (a GET may
  /// carry it in the cookie the page gets with index.html instead). The page reads it from the
  /// index.html it is served; a request without it, or from another Host or Origin, gets 403.
  const std::string& token() const;
  /// The Host header values accepted: the bound address, localhost, 127.0.0.1 and [::1] with the
  /// port (empty before bind()).
  const std::vector<std::string>& allowed_hosts() const;
  /// Serves one connection whose bytes are `request` (through a socket pair, as a client's would
  /// be) and returns the bytes the server answered: for tests and fuzzing without a port.
  std::string answer(const std::string& request);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace caps::server
