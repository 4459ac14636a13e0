// brume — the front of `brume view`'s HTTP server: an epoll loop that reads
// request heads and bodies within bounds and deadlines, and workers that run
// the handler on complete requests (http_front.hpp says why and what).
#include "jobs/view/http_front.hpp"

#include "brume/error.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/epoll.h>
#include <sys/eventfd.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <limits>
#include <mutex>
#include <thread>
#include <tuple>
#include <unordered_map>

namespace brume::view {

namespace {

long long front_now_ms() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

bool iequals(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i)
    if (std::tolower(static_cast<unsigned char>(a[i])) != std::tolower(static_cast<unsigned char>(b[i]))) return false;
  return true;
}

std::string_view trim_ows(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r')) s.remove_suffix(1);
  return s;
}

// The line [from, '\n'] of `buf` without its CR LF, or npos for `end` when
// the line is not complete.
struct Line {
  std::string_view text;
  std::size_t next = std::string::npos;  // offset after its '\n'
};
Line line_at(const std::string& buf, std::size_t from) {
  const std::size_t nl = buf.find('\n', from);
  if (nl == std::string::npos) return {};
  std::string_view t(buf.data() + from, nl - from);
  if (!t.empty() && t.back() == '\r') t.remove_suffix(1);
  return {t, nl + 1};
}

std::string addr_text(const sockaddr_storage& a, int& port) {
  char b[INET6_ADDRSTRLEN] = "";
  if (a.ss_family == AF_INET) {
    const auto* v = reinterpret_cast<const sockaddr_in*>(&a);
    inet_ntop(AF_INET, &v->sin_addr, b, sizeof b);
    port = ntohs(v->sin_port);
  } else if (a.ss_family == AF_INET6) {
    const auto* v = reinterpret_cast<const sockaddr_in6*>(&a);
    inet_ntop(AF_INET6, &v->sin6_addr, b, sizeof b);
    port = ntohs(v->sin6_port);
  }
  return b;
}

enum class Phase { head, body, busy, closing };

struct Conn {
  int fd = -1;
  std::uint64_t order = 0;  // accept order (ties of t0)
  Phase phase = Phase::head;
  std::string buf;    // received, not yet handed to a worker
  long long t0 = 0;   // ms: accepted, or its previous response ended (head); head's end (body)
  bool kept = false;  // a keep-alive connection between requests
  int served = 0;
  // head
  std::size_t scanned = 0;  // lines of the head read so far end here
  std::size_t lines = 0;
  std::size_t head_len = 0;
  // body
  bool chunked = false;
  std::size_t content_length = 0;
  std::size_t pos = 0;  // chunked: the parse position in buf
  std::size_t chunk_left = 0;
  int chunk_state = 0;  // 0 size line, 1 data, 2 trailer
  std::size_t decoded = 0;
  // closing
  long long linger_until = 0;
  std::size_t lingered = 0;
};

struct Job {
  int fd;
  std::string request;
  bool last;
};

}  // namespace

int listen_socket(const std::string& addr, int port, std::string& error) {
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  hints.ai_flags = AI_PASSIVE | AI_NUMERICSERV;
  addrinfo* res = nullptr;
  const std::string service = std::to_string(port);
  if (const int rc = getaddrinfo(addr.c_str(), service.c_str(), &hints, &res); rc != 0) {
    error = gai_strerror(rc);
    return -1;
  }
  int fd = -1;
  for (addrinfo* ai = res; ai; ai = ai->ai_next) {
    fd = ::socket(ai->ai_family, ai->ai_socktype | SOCK_NONBLOCK | SOCK_CLOEXEC, ai->ai_protocol);
    if (fd < 0) continue;
    const int one = 1;
    setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    if (ai->ai_family == AF_INET6) setsockopt(fd, IPPROTO_IPV6, IPV6_V6ONLY, &one, sizeof one);
    if (::bind(fd, ai->ai_addr, ai->ai_addrlen) == 0 && ::listen(fd, SOMAXCONN) == 0) break;
    error = std::strerror(errno);
    ::close(fd);
    fd = -1;
  }
  freeaddrinfo(res);
  return fd;
}

int socket_port(int fd) {
  sockaddr_storage a{};
  socklen_t n = sizeof a;
  if (getsockname(fd, reinterpret_cast<sockaddr*>(&a), &n) != 0) return -1;
  int port = -1;
  addr_text(a, port);
  return port;
}

struct HttpFront::Impl {
  std::vector<int> listeners;
  FrontLimits lim;
  FrontAdmit admit;
  std::string refusal;
  FrontHandler handler;

  int ep = -1, wake = -1;
  std::atomic<bool> stopping{false};
  std::thread loop_thread;
  std::vector<std::thread> workers;

  // Loop thread only.
  std::unordered_map<int, std::unique_ptr<Conn>> conns;
  std::uint64_t next_order = 0;
  long long accept_paused_until = 0;

  // Between the loop and the workers.
  std::mutex mu;
  std::condition_variable cv;
  std::deque<Job> jobs;
  std::deque<std::pair<int, bool>> returned;  // (fd, keep open)

  mutable std::mutex stats_mu;
  FrontStats st;

  void count(std::size_t FrontStats::*field) {
    std::lock_guard<std::mutex> l(stats_mu);
    ++(st.*field);
  }

  // ------------------------------------------------------------ the loop

  void watch(int fd, bool on) {
    epoll_event e{};
    e.events = EPOLLIN | EPOLLRDHUP;
    e.data.fd = fd;
    epoll_ctl(ep, on ? EPOLL_CTL_ADD : EPOLL_CTL_DEL, fd, on ? &e : nullptr);
  }

  void close_conn(int fd) {
    auto it = conns.find(fd);
    if (it == conns.end()) return;
    if (it->second->phase != Phase::busy) watch(fd, false);
    ::close(fd);
    conns.erase(it);
  }

  // A refusal from the front: a short response, then the connection is shut
  // for writing and what the peer still sends is read and dropped for a
  // while (so that a client still sending its body sees the response rather
  // than a reset), then closed.
  void refuse(Conn& c, int status, const char* reason, const std::string& body) {
    std::string r = "HTTP/1.1 " + std::to_string(status) + " " + reason +
                    "\r\nContent-Type: text/plain; charset=utf-8\r\nContent-Length: " + std::to_string(body.size()) +
                    "\r\nConnection: close\r\nCache-Control: no-store\r\nX-Content-Type-Options: nosniff\r\n\r\n" +
                    body;
    (void)::send(c.fd, r.data(), r.size(), MSG_NOSIGNAL | MSG_DONTWAIT);  // small: fits the socket's buffer
    ::shutdown(c.fd, SHUT_WR);
    c.phase = Phase::closing;
    c.buf.clear();
    c.buf.shrink_to_fit();
    c.linger_until = front_now_ms() + lim.linger_ms;
    c.lingered = 0;
  }

  // The victim when the cap is reached: a connection being closed, else the
  // oldest pre-request one (silent, idle keep-alive or a partial head: the
  // one that has had the longest to send a request), else the oldest partial
  // body. Busy ones (a worker has their complete request) are never evicted.
  // A request from the page is complete within milliseconds of its
  // connection, so it is the newest and goes last.
  Conn* victim() {
    Conn* best = nullptr;
    int best_rank = 99;
    for (auto& [fd, c] : conns) {
      const int rank = c->phase == Phase::closing ? 0 : c->phase == Phase::head ? 1 : c->phase == Phase::body ? 2 : 99;
      if (rank < best_rank ||
          (rank == best_rank && best && std::tie(c->t0, c->order) < std::tie(best->t0, best->order))) {
        best = c.get();
        best_rank = rank;
      }
    }
    return best_rank < 99 ? best : nullptr;
  }

  bool evict_one() {
    Conn* v = victim();
    if (!v) return false;
    count(&FrontStats::evicted);
    close_conn(v->fd);
    return true;
  }

  void pause_accepting(long long now) {
    accept_paused_until = now + 100;
    for (int l : listeners) watch(l, false);
  }

  void on_accept(int lfd) {
    for (int n = 0; n < 256; ++n) {  // a batch, then the other events get their turn
      const int fd = ::accept4(lfd, nullptr, nullptr, SOCK_NONBLOCK | SOCK_CLOEXEC);
      if (fd < 0) {
        if (errno == EINTR || errno == ECONNABORTED) continue;
        if (errno == EMFILE || errno == ENFILE || errno == ENOBUFS || errno == ENOMEM) {
          // Out of descriptors: make room if a connection can go, else wait.
          if (evict_one()) continue;
          pause_accepting(front_now_ms());
        }
        return;
      }
      if (conns.size() >= lim.max_connections && !evict_one()) {
        ::close(fd);  // every connection has a complete request in a worker's hands
        continue;
      }
      auto c = std::make_unique<Conn>();
      c->fd = fd;
      c->order = next_order++;
      c->t0 = front_now_ms();
      watch(fd, true);
      Conn& added = *c;
      conns.emplace(fd, std::move(c));
      count(&FrontStats::accepted);
      // Its request may be there already: read it before the next accept can
      // evict it (a complete request goes to a worker, out of reach).
      on_readable(added);
    }
  }

  void to_worker(Conn& c, std::size_t end) {
    Job j{c.fd, c.buf.substr(0, end), false};
    c.buf.erase(0, end);
    ++c.served;
    j.last = c.served >= lim.max_requests;
    c.phase = Phase::busy;
    watch(c.fd, false);
    {
      std::lock_guard<std::mutex> l(mu);
      jobs.push_back(std::move(j));
    }
    cv.notify_one();
  }

  // Reads what the head and body bounds allow; hands a complete request on,
  // refuses a request past a bound. Returns false when the connection was
  // closed.
  bool advance(Conn& c) {
    if (c.phase == Phase::head) {
      while (true) {
        const Line l = line_at(c.buf, c.scanned);
        if (l.next == std::string::npos) {
          const std::size_t partial = c.buf.size() - c.scanned;
          if (partial > lim.max_line_bytes || c.buf.size() > lim.max_head_bytes) {
            count(&FrontStats::refused_head);
            refuse(c, 431, "Request Header Fields Too Large", "request head too large\n");
          }
          return true;
        }
        // The request line and at most max_header_lines fields; the blank line that ends the head is not one.
        if (!l.text.empty()) ++c.lines;
        if (l.text.size() > lim.max_line_bytes || l.next > lim.max_head_bytes || c.lines > lim.max_header_lines + 1) {
          count(&FrontStats::refused_head);
          refuse(c, 431, "Request Header Fields Too Large", "request head too large\n");
          return true;
        }
        c.scanned = l.next;
        if (l.text.empty()) break;
      }
      c.head_len = c.scanned;
      if (!parse_head(c)) return true;  // refused
      if (c.phase == Phase::head) {     // no body
        to_worker(c, c.head_len);
        return true;
      }
    }
    if (c.phase == Phase::body) {
      if (!c.chunked) {
        if (c.buf.size() >= c.head_len + c.content_length) to_worker(c, c.head_len + c.content_length);
        return true;
      }
      return chunks(c);
    }
    return true;
  }

  // The request line and the framing headers; moves to the body phase, or
  // refuses. The rest of the head is the handler's to read.
  bool parse_head(Conn& c) {
    const Line first = line_at(c.buf, 0);
    const std::string_view rl = first.text;
    const std::size_t s1 = rl.find(' '), s2 = s1 == std::string::npos ? s1 : rl.find(' ', s1 + 1);
    if (s1 == std::string::npos || s2 == std::string::npos || s1 == 0) {
      count(&FrontStats::refused_head);
      refuse(c, 400, "Bad Request", "bad request line\n");
      return false;
    }
    const std::string_view target = rl.substr(s1 + 1, s2 - s1 - 1), version = rl.substr(s2 + 1);
    if (version != "HTTP/1.1" && version != "HTTP/1.0") {
      count(&FrontStats::refused_head);
      refuse(c, 400, "Bad Request", "bad request line\n");
      return false;
    }
    // The token first: a request without it is never read further.
    if (!admit(target)) {
      count(&FrontStats::refused_token);
      refuse(c, 403, "Forbidden", refusal);
      return false;
    }
    bool has_length = false, has_te = false;
    std::size_t length = 0;
    for (std::size_t at = first.next; at < c.head_len;) {
      const Line l = line_at(c.buf, at);
      at = l.next;
      const std::size_t colon = l.text.find(':');
      if (colon == std::string::npos) continue;  // the handler refuses it
      const std::string_view name = l.text.substr(0, colon), value = trim_ows(l.text.substr(colon + 1));
      if (iequals(name, "content-length")) {
        // Digits only; leading zeros are allowed (RFC 9110: 1*DIGIT). Past 18
        // significant digits the value saturates: above any body bound, so 413.
        std::size_t v = 0;
        bool ok = !value.empty();
        int significant = 0;
        for (char ch : value) {
          ok = ok && ch >= '0' && ch <= '9';
          if (!ok) break;
          if (significant == 0 && ch == '0') continue;
          v = ++significant > 18 ? std::numeric_limits<std::size_t>::max() : v * 10 + static_cast<std::size_t>(ch - '0');
        }
        if (!ok || (has_length && v != length)) {
          count(&FrontStats::refused_head);
          refuse(c, 400, "Bad Request", "bad Content-Length\n");
          return false;
        }
        has_length = true;
        length = v;
      } else if (iequals(name, "transfer-encoding")) {
        if (!iequals(value, "chunked") || has_te) {
          count(&FrontStats::refused_head);
          refuse(c, 501, "Not Implemented", "only the chunked transfer coding is understood\n");
          return false;
        }
        has_te = true;
      }
    }
    if (has_te && has_length) {
      count(&FrontStats::refused_head);
      refuse(c, 400, "Bad Request", "both Content-Length and Transfer-Encoding\n");
      return false;
    }
    if (has_length && length > lim.max_body_bytes) {
      count(&FrontStats::refused_body);
      refuse(c, 413, "Payload Too Large", "request body above " + std::to_string(lim.max_body_bytes) + " bytes\n");
      return false;
    }
    if (has_te || (has_length && length > 0)) {
      c.phase = Phase::body;
      c.chunked = has_te;
      c.content_length = length;
      c.pos = c.head_len;
      c.chunk_state = 0;
      c.decoded = 0;
      c.t0 = front_now_ms();
    }
    return true;
  }

  // The chunked body's framing as far as it has arrived; bounds the data and
  // the framing separately (a body of one-byte chunks is six times its data).
  bool chunks(Conn& c) {
    auto too_large = [&] {
      count(&FrontStats::refused_body);
      refuse(c, 413, "Payload Too Large", "request body above " + std::to_string(lim.max_body_bytes) + " bytes\n");
      return true;
    };
    auto bad = [&] {
      count(&FrontStats::refused_body);
      refuse(c, 400, "Bad Request", "bad chunked framing\n");
      return true;
    };
    while (true) {
      if (c.pos - c.head_len - c.decoded > lim.max_framing_bytes) return too_large();
      if (c.chunk_state == 1) {
        if (c.buf.size() < c.pos + c.chunk_left + 2) {
          // Without its CR LF: is the data alone already too much?
          return true;
        }
        if (c.buf.compare(c.pos + c.chunk_left, 2, "\r\n") != 0) return bad();
        c.pos += c.chunk_left + 2;
        c.decoded += c.chunk_left;
        c.chunk_state = 0;
        continue;
      }
      const Line l = line_at(c.buf, c.pos);
      if (l.next == std::string::npos) {
        if (c.buf.size() - c.pos > lim.max_line_bytes) return c.chunk_state == 0 ? bad() : too_large();
        return true;
      }
      if (l.text.size() > lim.max_line_bytes) return bad();
      c.pos = l.next;
      if (c.chunk_state == 2) {  // trailers, until an empty line
        if (l.text.empty()) {
          to_worker(c, c.pos);
          return true;
        }
        continue;
      }
      std::string_view hex = l.text.substr(0, l.text.find(';'));
      hex = trim_ows(hex);
      if (hex.empty() || hex.size() > 8) return hex.size() > 8 ? too_large() : bad();
      std::size_t n = 0;
      for (char ch : hex) {
        const int d = ch >= '0' && ch <= '9'   ? ch - '0'
                      : ch >= 'a' && ch <= 'f' ? ch - 'a' + 10
                      : ch >= 'A' && ch <= 'F' ? ch - 'A' + 10
                                               : -1;
        if (d < 0) return bad();
        n = n * 16 + static_cast<std::size_t>(d);
      }
      if (c.decoded + n > lim.max_body_bytes) return too_large();
      c.chunk_left = n;
      c.chunk_state = n == 0 ? 2 : 1;
    }
  }

  void on_readable(Conn& c) {
    char b[65536];
    // A bounded read per event: the other connections get their turn.
    for (int n = 0; n < 4; ++n) {
      const ssize_t r = ::recv(c.fd, b, sizeof b, 0);
      if (r > 0) {
        if (c.phase == Phase::closing) {
          c.lingered += static_cast<std::size_t>(r);
          if (c.lingered > lim.linger_bytes) {
            close_conn(c.fd);
            return;
          }
          continue;
        }
        c.buf.append(b, static_cast<std::size_t>(r));
        if (c.phase == Phase::head || c.phase == Phase::body) {
          const int fd = c.fd;
          advance(c);
          if (!conns.count(fd) || c.phase == Phase::busy) return;
        }
        continue;
      }
      if (r == 0 || (errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR)) {
        close_conn(c.fd);  // the peer closed (a complete request was handed on above)
        return;
      }
      if (errno == EINTR) continue;
      return;
    }
  }

  // Deadlines, checked every ~100 ms.
  void sweep(long long now) {
    std::vector<int> gone;
    for (auto& [fd, c] : conns) {
      switch (c->phase) {
        case Phase::head:
          if (c->kept && c->buf.empty() && now - c->t0 > lim.keep_alive_ms) {
            count(&FrontStats::idle_closed);
            gone.push_back(fd);
          } else if (now - c->t0 > lim.head_deadline_ms) {
            if (c->kept && c->buf.empty()) count(&FrontStats::idle_closed);
            else count(&FrontStats::head_timeouts);
            gone.push_back(fd);
          }
          break;
        case Phase::body:
          if (now - c->t0 > lim.body_deadline_ms) gone.push_back(fd);
          break;
        case Phase::closing:
          if (now > c->linger_until) gone.push_back(fd);
          break;
        case Phase::busy: break;
      }
    }
    for (int fd : gone) close_conn(fd);
    if (accept_paused_until && now >= accept_paused_until) {
      accept_paused_until = 0;
      for (int l : listeners) watch(l, true);
    }
  }

  void take_returned() {
    std::deque<std::pair<int, bool>> r;
    {
      std::lock_guard<std::mutex> l(mu);
      r.swap(returned);
    }
    const long long now = front_now_ms();
    for (auto [fd, keep] : r) {
      auto it = conns.find(fd);
      if (it == conns.end()) continue;
      Conn& c = *it->second;
      if (!keep) {
        ::close(fd);
        conns.erase(it);
        continue;
      }
      c.phase = Phase::head;
      c.kept = true;
      c.t0 = now;
      c.scanned = c.lines = c.head_len = 0;
      c.chunked = false;
      c.content_length = 0;
      watch(fd, true);
      if (!c.buf.empty()) advance(c);  // a pipelined request
    }
  }

  void loop() {
    for (int l : listeners) watch(l, true);
    epoll_event w{};
    w.events = EPOLLIN;
    w.data.fd = wake;
    epoll_ctl(ep, EPOLL_CTL_ADD, wake, &w);
    std::vector<epoll_event> ev(256);
    long long last_sweep = front_now_ms();
    while (!stopping.load()) {
      const int n = epoll_wait(ep, ev.data(), static_cast<int>(ev.size()), 100);
      for (int i = 0; i < n && !stopping.load(); ++i) {
        const int fd = ev[i].data.fd;
        if (fd == wake) {
          std::uint64_t v;
          (void)::read(wake, &v, sizeof v);
          take_returned();
          continue;
        }
        if (std::find(listeners.begin(), listeners.end(), fd) != listeners.end()) {
          on_accept(fd);
          continue;
        }
        auto it = conns.find(fd);
        if (it == conns.end() || it->second->phase == Phase::busy) continue;
        on_readable(*it->second);
      }
      const long long now = front_now_ms();
      if (now - last_sweep >= 100) {
        sweep(now);
        last_sweep = now;
      }
    }
  }

  // ------------------------------------------------------------ workers

  bool write_all(int fd, const char* p, std::size_t n) {
    long long progress = front_now_ms();
    while (n > 0) {
      if (stopping.load()) return false;
      const ssize_t w = ::send(fd, p, n, MSG_NOSIGNAL);
      if (w > 0) {
        p += w;
        n -= static_cast<std::size_t>(w);
        progress = front_now_ms();
        continue;
      }
      if (w < 0 && errno == EINTR) continue;
      if (w < 0 && errno != EAGAIN && errno != EWOULDBLOCK) return false;
      if (front_now_ms() - progress > lim.write_stall_ms) return false;
      pollfd q{fd, POLLOUT, 0};
      (void)::poll(&q, 1, 100);  // wakes to look at `stopping`
    }
    return true;
  }

  void work() {
    while (true) {
      Job j;
      {
        std::unique_lock<std::mutex> l(mu);
        cv.wait(l, [&] { return stopping.load() || !jobs.empty(); });
        if (stopping.load()) return;
        j = std::move(jobs.front());
        jobs.pop_front();
      }
      FrontPeer peer;
      sockaddr_storage a{};
      socklen_t len = sizeof a;
      if (getpeername(j.fd, reinterpret_cast<sockaddr*>(&a), &len) == 0)
        peer.remote_ip = addr_text(a, peer.remote_port);
      len = sizeof a;
      if (getsockname(j.fd, reinterpret_cast<sockaddr*>(&a), &len) == 0) peer.local_ip = addr_text(a, peer.local_port);
      bool keep = false;
      try {
        keep = handler(j.request, j.last, peer, [&](const char* p, std::size_t n) { return write_all(j.fd, p, n); });
      } catch (...) {
        keep = false;  // the handler answers its own errors; nothing escapes into the response
      }
      count(&FrontStats::handled);
      {
        std::lock_guard<std::mutex> l(mu);
        returned.emplace_back(j.fd, keep && !j.last);
      }
      const std::uint64_t one = 1;
      (void)::write(wake, &one, sizeof one);
    }
  }
};

HttpFront::HttpFront(std::vector<int> listeners, FrontLimits limits, FrontAdmit admit, std::string refusal,
                     FrontHandler handler)
    : impl_(std::make_unique<Impl>()) {
  impl_->listeners = std::move(listeners);
  impl_->lim = limits;
  impl_->admit = std::move(admit);
  impl_->refusal = std::move(refusal);
  impl_->handler = std::move(handler);
  impl_->ep = epoll_create1(EPOLL_CLOEXEC);
  impl_->wake = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  if (impl_->ep < 0 || impl_->wake < 0) {
    const std::string why = std::strerror(errno);
    if (impl_->ep >= 0) ::close(impl_->ep);
    if (impl_->wake >= 0) ::close(impl_->wake);
    throw Error("brume view: cannot create the server's event queue (" + why +
                "); the process may have run out of file descriptors (ulimit -n)");
  }
}

HttpFront::~HttpFront() {
  stop();
  if (impl_->ep >= 0) ::close(impl_->ep);
  if (impl_->wake >= 0) ::close(impl_->wake);
}

void HttpFront::start() {
  Impl& m = *impl_;
  for (int i = 0; i < m.lim.workers; ++i) m.workers.emplace_back([&m] { m.work(); });
  m.loop_thread = std::thread([&m] { m.loop(); });
}

void HttpFront::stop() {
  Impl& m = *impl_;
  if (!m.loop_thread.joinable() && m.workers.empty()) {
    for (int l : m.listeners) ::close(l);
    m.listeners.clear();
    return;
  }
  {
    std::lock_guard<std::mutex> l(m.mu);
    m.stopping.store(true);
  }
  m.cv.notify_all();
  const std::uint64_t one = 1;
  (void)::write(m.wake, &one, sizeof one);
  if (m.loop_thread.joinable()) m.loop_thread.join();
  for (std::thread& t : m.workers) t.join();  // a handler call in progress ends; its writes give up at once
  m.workers.clear();
  for (auto& [fd, c] : m.conns) ::close(fd);
  m.conns.clear();
  for (int l : m.listeners) ::close(l);
  m.listeners.clear();
}

FrontStats HttpFront::stats() const {
  std::lock_guard<std::mutex> l(impl_->stats_mu);
  return impl_->st;
}

}  // namespace brume::view
