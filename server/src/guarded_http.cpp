#include "guarded_http.hpp"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <cstring>
#include <deque>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace caps::server::detail {

namespace {

using Clock = std::chrono::steady_clock;

Clock::time_point after(Clock::time_point t, double seconds) {
  return t + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(seconds));
}

thread_local ConnectionState* t_connection = nullptr;

// Waits until `sock` is ready for `events` or `deadline` passes or `stopping()` (polled every
// 100 ms, so that a stop is not held up by a silent client). True when ready.
bool wait_for(int sock, short events, Clock::time_point deadline,
              const std::function<bool()>& stopping) {
  for (;;) {
    if (stopping()) return false;
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now());
    if (left.count() <= 0) return false;
    pollfd p{sock, events, 0};
    const int r = ::poll(&p, 1, static_cast<int>(std::min<long long>(left.count(), 100)));
    if (r > 0) return true;
    if (r < 0 && errno != EINTR) return false;
  }
}

// A connection's bytes under the limits: the headers before their deadline (the request's first
// byte + header_timeout_s; bytes dripping in do not move it), the body and the response at
// min_bytes_per_s after a grace time, the body no larger than max_body_bytes.
class DeadlineStream : public httplib::Stream {
 public:
  DeadlineStream(int sock, const ConnectionLimits& limits, ConnectionState& state,
                 std::function<bool()> stopping)
      : sock_(sock), limits_(limits), state_(state), stopping_(std::move(stopping)) {}

  // A new request: its headers are due header_timeout_s from now.
  void begin_request() {
    phase_ = Phase::Headers;
    header_bytes_ = 0;
    tail_ = 0;
    header_deadline_ = after(Clock::now(), limits_.header_timeout_s);
  }
  bool has_buffered() const { return begin_ < end_; }
  // Waits for a next request's first byte for keep_alive_s; false: close the connection.
  bool wait_next_request() {
    if (has_buffered()) return true;
    if (!wait_for(sock_, POLLIN, after(Clock::now(), limits_.keep_alive_s), stopping_)) return false;
    return fill(after(Clock::now(), limits_.keep_alive_s)) > 0;
  }

  bool is_readable() const override { return has_buffered(); }
  bool is_writable() const override {
    pollfd p{sock_, POLLOUT, 0};
    return ::poll(&p, 1, 0) > 0 && !(p.revents & (POLLERR | POLLHUP));
  }

  ssize_t read(char* ptr, std::size_t size) override {
    if (!has_buffered() && fill(read_deadline()) <= 0) return -1;
    std::size_t n = std::min(size, end_ - begin_);
    if (phase_ == Phase::Headers) {
      // Byte by byte up to the blank line that ends the headers: what follows is the body's.
      std::size_t i = 0;
      while (i < n && phase_ == Phase::Headers) {
        tail_ = (tail_ << 8) | static_cast<unsigned char>(buffer_[begin_ + i]);
        ++i;
        if ((tail_ & 0xffffffffu) == 0x0d0a0d0au || (tail_ & 0xffffu) == 0x0a0au) {
          phase_ = Phase::Body;
          body_start_ = Clock::now();
          body_bytes_ = 0;
        }
      }
      header_bytes_ += i;
      n = i;
      if (header_bytes_ > limits_.max_header_bytes) return -1;
    } else {
      if (body_bytes_ + n > limits_.max_body_bytes) {
        state_.body_too_large = true;
        state_.close = true;
        return -1;
      }
      body_bytes_ += n;
    }
    std::memcpy(ptr, buffer_.data() + begin_, n);
    begin_ += n;
    return static_cast<ssize_t>(n);
  }

  ssize_t write(const char* ptr, std::size_t size) override {
    if (phase_ != Phase::Responding) {
      phase_ = Phase::Responding;
      response_start_ = Clock::now();
      response_bytes_ = 0;
    }
    const auto deadline = after(response_start_, limits_.transfer_grace_s +
                                                     static_cast<double>(response_bytes_ + size) /
                                                         limits_.min_bytes_per_s);
    std::size_t sent = 0;
    while (sent < size) {
      if (!wait_for(sock_, POLLOUT, deadline, stopping_))
        return sent ? static_cast<ssize_t>(sent) : -1;
      const ssize_t n = ::send(sock_, ptr + sent, size - sent, MSG_NOSIGNAL);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) return sent ? static_cast<ssize_t>(sent) : -1;
      sent += static_cast<std::size_t>(n);
    }
    response_bytes_ += sent;
    return static_cast<ssize_t>(sent);
  }

  void get_remote_ip_and_port(std::string& ip, int& port) const override {
    address(::getpeername, ip, port);
  }
  void get_local_ip_and_port(std::string& ip, int& port) const override {
    address(::getsockname, ip, port);
  }
  socket_t socket() const override { return sock_; }

 private:
  enum class Phase { Headers, Body, Responding };

  Clock::time_point read_deadline() const {
    if (phase_ == Phase::Headers) return header_deadline_;
    return after(body_start_, limits_.transfer_grace_s +
                                  static_cast<double>(body_bytes_) / limits_.min_bytes_per_s);
  }

  // Reads what the socket holds into the buffer (waiting until `deadline`); its count, 0 at the
  // end of the stream, -1 on a timeout or an error.
  ssize_t fill(Clock::time_point deadline) {
    begin_ = end_ = 0;
    if (!wait_for(sock_, POLLIN, deadline, stopping_)) return -1;
    ssize_t n;
    do n = ::recv(sock_, buffer_.data(), buffer_.size(), 0);
    while (n < 0 && errno == EINTR);
    if (n > 0) end_ = static_cast<std::size_t>(n);
    return n;
  }

  template <class Name>
  void address(Name name, std::string& ip, int& port) const {
    sockaddr_storage a{};
    socklen_t len = sizeof(a);
    ip.clear();
    port = 0;
    if (name(sock_, reinterpret_cast<sockaddr*>(&a), &len) != 0) return;
    char text[INET6_ADDRSTRLEN] = {};
    if (a.ss_family == AF_INET) {
      const auto* v4 = reinterpret_cast<const sockaddr_in*>(&a);
      ::inet_ntop(AF_INET, &v4->sin_addr, text, sizeof(text));
      port = ntohs(v4->sin_port);
    } else if (a.ss_family == AF_INET6) {
      const auto* v6 = reinterpret_cast<const sockaddr_in6*>(&a);
      ::inet_ntop(AF_INET6, &v6->sin6_addr, text, sizeof(text));
      port = ntohs(v6->sin6_port);
    }
    ip = text;
  }

  int sock_;
  const ConnectionLimits& limits_;
  ConnectionState& state_;
  std::function<bool()> stopping_;
  std::vector<char> buffer_ = std::vector<char>(16 * 1024);
  std::size_t begin_ = 0, end_ = 0;
  Phase phase_ = Phase::Headers;
  std::uint64_t tail_ = 0;  // the last bytes of the headers, to find the blank line
  std::size_t header_bytes_ = 0, body_bytes_ = 0, response_bytes_ = 0;
  Clock::time_point header_deadline_, body_start_, response_start_;
};

// A thread per connection, kept for the next when idle, never more than `max_threads` (more
// connections wait for one): httplib's fixed pool of 8 let 8 slow clients stop the server.
class ConnectionThreads : public httplib::TaskQueue {
 public:
  explicit ConnectionThreads(std::size_t max_threads) : max_threads_(max_threads) {}
  ~ConnectionThreads() override { shutdown(); }

  void enqueue(std::function<void()> fn) override {
    std::lock_guard<std::mutex> lock(m_);
    jobs_.push_back(std::move(fn));
    if (jobs_.size() > idle_ && threads_.size() < max_threads_)
      threads_.emplace_back([this] { work(); });
    cv_.notify_one();
  }

  void shutdown() override {
    {
      std::lock_guard<std::mutex> lock(m_);
      if (shut_) return;
      shut_ = true;
    }
    cv_.notify_all();
    for (std::thread& t : threads_) t.join();
  }

 private:
  void work() {
    for (;;) {
      std::function<void()> job;
      {
        std::unique_lock<std::mutex> lock(m_);
        ++idle_;
        cv_.wait(lock, [this] { return shut_ || !jobs_.empty(); });
        --idle_;
        if (jobs_.empty()) return;
        job = std::move(jobs_.front());
        jobs_.pop_front();
      }
      job();
    }
  }

  std::size_t max_threads_;
  std::mutex m_;
  std::condition_variable cv_;
  std::deque<std::function<void()>> jobs_;
  std::vector<std::thread> threads_;
  std::size_t idle_ = 0;
  bool shut_ = false;
};

constexpr char kBusy[] =
    "HTTP/1.1 503 Service Unavailable\r\nContent-Type: application/json\r\nConnection: close\r\n"
    "Content-Length: 78\r\n\r\n"
    "{\"error\": \"the planner server has too many connections open; try again later\"}";
static_assert(sizeof(kBusy) - 1 - std::string_view(kBusy).find("\r\n\r\n") - 4 == 78);

}  // namespace

GuardedHttpServer::GuardedHttpServer(ConnectionLimits limits) : limits_(limits) {
  // Rejected connections are answered by threads beyond the cap, so that a full server still
  // says so at once.
  const std::size_t threads = static_cast<std::size_t>(std::max(1, limits_.max_connections)) + 8;
  new_task_queue = [threads] { return new ConnectionThreads(threads); };
  set_payload_max_length(limits_.max_body_bytes);
}

ConnectionState* GuardedHttpServer::current() { return t_connection; }

void GuardedHttpServer::widen_backlog(int backlog) {
  const socket_t sock = svr_sock_;
  if (sock != INVALID_SOCKET) ::listen(sock, backlog);  // a listening socket takes a new backlog
}

bool GuardedHttpServer::process_and_close_socket(socket_t sock) {
  struct Count {
    std::atomic<int>& n;
    ~Count() { --n; }
  } count{n_connections_};
  const int open = ++n_connections_;
  bool ret = false;
  if (open > limits_.max_connections) {
    (void)::send(sock, kBusy, sizeof(kBusy) - 1, MSG_NOSIGNAL);
  } else {
    ConnectionState state;
    const std::atomic<socket_t>& listening = svr_sock_;
    // Served from the listening loop: stop() closes the listening socket. Served by hand
    // (serve_socket() before any listen): never stopped.
    const bool from_loop = listening != INVALID_SOCKET;
    DeadlineStream strm(sock, limits_, state,
                        [&listening, from_loop] { return from_loop && listening == INVALID_SOCKET; });
    t_connection = &state;
    std::size_t left = static_cast<std::size_t>(std::max<std::size_t>(1, keep_alive_max_count_));
    bool first = true;
    while (left > 0 && (first || strm.wait_next_request())) {
      first = false;
      strm.begin_request();
      state = ConnectionState{};
      bool closed = false;
      ret = process_request(strm, left == 1, closed, nullptr);
      if (!ret || closed || state.close) break;
      --left;
    }
    t_connection = nullptr;
  }
  // A lingering close: closing with the client's bytes unread (a refused body) sends a reset
  // that can drop the answer before the client reads it; so the answer is ended, and what comes
  // is read away for at most a second, until the client closes.
  ::shutdown(sock, SHUT_WR);
  const auto until = after(Clock::now(), 1.0);
  const std::atomic<socket_t>& listening = svr_sock_;
  const bool from_loop = listening != INVALID_SOCKET;
  char sink[16 * 1024];
  while (wait_for(sock, POLLIN, until, [&] { return from_loop && listening == INVALID_SOCKET; }) &&
         ::recv(sock, sink, sizeof(sink), 0) > 0) {
  }
  ::close(sock);
  return ret;
}

}  // namespace caps::server::detail
