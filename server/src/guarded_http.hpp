#pragma once
/// @brief The planner server's HTTP connections (cpp-httplib underneath): each connection on a
/// thread of its own up to a cap (more are answered 503 at once), the request's headers within a
/// total time and its body and response at a minimum rate, so that a client sending a byte at a
/// time cannot hold the server (docs/reliability.md, "The local planner server").

#include <httplib.h>

#include <atomic>
#include <cstddef>
#include <string>

namespace caps::server::detail {

/// The limits of one connection. Times in seconds, rates in bytes per second.
struct ConnectionLimits {
  /// The request line and every header within this time of the request's first byte (or of
  /// the connection's opening): a byte now and then does not extend it.
  double header_timeout_s = 10;
  /// The body (and the response) may take this long plus a byte per 1/min_rate seconds.
  double transfer_grace_s = 10;
  double min_bytes_per_s = 16 * 1024;
  /// An idle connection between requests is closed after this long.
  double keep_alive_s = 5;
  /// The request line and headers, bytes (httplib limits each line to 8 KiB).
  std::size_t max_header_bytes = 64 * 1024;
  /// The request body as sent (chunked framing included), bytes; more: 413.
  std::size_t max_body_bytes = std::size_t{1} << 20;
  /// Connections served at once; more are answered 503 and closed at once.
  int max_connections = 256;
};

/// What the handlers of a request learn about its connection (GuardedHttpServer::current()).
struct ConnectionState {
  bool body_too_large = false;  ///< the body passed max_body_bytes (the answer: 413)
  bool close = false;           ///< close the connection after this answer
};

/// httplib::Server whose connections are served under ConnectionLimits.
class GuardedHttpServer : public httplib::Server {
 public:
  explicit GuardedHttpServer(ConnectionLimits limits);
  /// Serves the connection `sock` to its end and closes it (as the listening loop does): for
  /// tests and the fuzz target, which feed a socket pair.
  bool serve_socket(int sock) { return process_and_close_socket(sock); }
  /// The connection the calling thread is answering (in a handler), or null.
  static ConnectionState* current();
  /// Lets `backlog` connections wait to be accepted (httplib's listen() lets 5: a sixth client
  /// connecting at once waits for its SYN to be sent again, a second later). After binding.
  void widen_backlog(int backlog = 1024);
  /// Connections being served now.
  int n_connections() const { return n_connections_.load(); }
  const ConnectionLimits& limits() const { return limits_; }

 private:
  bool process_and_close_socket(socket_t sock) override;
  ConnectionLimits limits_;
  std::atomic<int> n_connections_{0};
};

}  // namespace caps::server::detail
