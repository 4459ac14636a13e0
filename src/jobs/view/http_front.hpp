// brume — the front of `brume view`'s HTTP server (issue #51; docs/reliability.md).
//
// A peer without the token must not be able to stall or swell the server.
// On loopback every peer, the browser included, is 127.0.0.1, so limits per
// client mean nothing; what holds is a bound on each thing a connection can
// make the server keep, and a deadline on each thing it can make it wait for.
// The front is one thread with an epoll loop over the listening sockets and
// every connection, and a few workers:
//
//   - a request head (request line and headers) is read with a byte bound
//     (the whole head, each line, the number of lines: 431) and must be
//     complete within a deadline of the connection's start, or of the end of
//     its previous response (2 s; an idle keep-alive connection is closed
//     after 1 s): a silent or trickling connection is closed, never waited on;
//   - at the connection cap, the idle pre-request connections are evicted
//     first (closing ones, then silent ones, then partial heads; the oldest
//     first), so a complete request is answered while hundreds hang on;
//   - a request whose target lacks the token gets 403 from the front itself
//     (and its body is never read); a token-bearing request's body is bounded
//     for every method and framing (Content-Length above the bound: 413 before
//     a byte of it is read; chunked: 413 once the chunks pass it), and must
//     arrive within its own deadline;
//   - only then is the complete request (head and body, as sent) handed to a
//     worker, which runs the handler (cpp-httplib's parsing and routes, in
//     view.cpp) and writes the response; the connection goes back to the loop
//     for keep-alive;
//   - stop() returns within ~0.1 s plus the handler calls in progress: the
//     loop closes every connection, and a response being written to a peer
//     that does not read is abandoned.
#pragma once

#include <cstddef>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace brume::view {

struct FrontLimits {
  std::size_t max_connections = 512;        // held at once (busy ones included)
  std::size_t max_head_bytes = 16384;       // request line and headers together
  std::size_t max_line_bytes = 8192;        // one line of the head (cpp-httplib's own URI bound)
  std::size_t max_header_lines = 100;       // header lines of one head
  std::size_t max_body_bytes = 1 << 20;     // a body, decoded (chunked: its data)
  std::size_t max_framing_bytes = 1 << 18;  // chunked framing (size lines, CRLFs, trailers) of one body
  int head_deadline_ms = 2000;              // a complete head, from the connection's start or its last response
  int keep_alive_ms = 1000;                 // an idle keep-alive connection without a byte of a next request
  int body_deadline_ms = 10000;             // a complete body, from the head's end
  int write_stall_ms = 5000;                // a response write making no progress
  int linger_ms = 1000;                     // after a refusal: read and drop what the peer still sends, then close
  std::size_t linger_bytes = 16 << 20;
  int max_requests = 100;  // per connection
  int workers = 4;
};

// The peer and local addresses of a connection, for the handler.
struct FrontPeer {
  std::string remote_ip, local_ip;
  int remote_port = 0, local_port = 0;
};

// Writes bytes of the response; false when the peer is gone, stalled past
// write_stall_ms, or the front is stopping.
using FrontWrite = std::function<bool(const char* data, std::size_t size)>;

// A complete request as it arrived (head and body, chunked framing kept); the
// handler writes the whole response and returns whether the connection may
// stay open. `last`: the connection closes after this response whatever the
// handler returns (its request cap, or the front is stopping).
using FrontHandler =
    std::function<bool(const std::string& request, bool last, const FrontPeer& peer, const FrontWrite& write)>;

// Whether a request target may be served (the token); others get 403 with
// `refusal` as the body, from the front.
using FrontAdmit = std::function<bool(std::string_view target)>;

// Counters for the tests and the docs (read after stop(), or racy but atomic).
struct FrontStats {
  std::size_t accepted = 0, evicted = 0, head_timeouts = 0, idle_closed = 0, refused_head = 0, refused_body = 0,
              refused_token = 0, handled = 0;
};

// A listening TCP socket on addr:port (port 0: a free one), non-blocking,
// with the system's largest backlog; IPv6 addresses bind only IPv6. Returns
// the descriptor, or -1 with `error` set.
int listen_socket(const std::string& addr, int port, std::string& error);
// The port a listening socket is bound to.
int socket_port(int fd);

class HttpFront {
 public:
  // Takes ownership of the listening descriptors.
  HttpFront(std::vector<int> listeners, FrontLimits limits, FrontAdmit admit, std::string refusal,
            FrontHandler handler);
  ~HttpFront();  // stops
  HttpFront(const HttpFront&) = delete;
  HttpFront& operator=(const HttpFront&) = delete;

  void start();
  // Closes every connection and the listeners; returns once the loop and the
  // workers have ended (a handler call in progress finishes first).
  void stop();
  FrontStats stats() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace brume::view
