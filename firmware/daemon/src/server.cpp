// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Server: the poll loop over sockets, the handshake, subscriptions, commands and each client's bounded queue.
#include "tofmat/daemon/server.hpp"

#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include <spdlog/spdlog.h>

#include <cerrno>
#include <deque>

#include "tofmat/daemon/log.hpp"
#include "tofmat/protocol/schema.hpp"

namespace tofmat::daemon {
namespace {

using Bytes = std::shared_ptr<const std::vector<std::uint8_t>>;
constexpr std::size_t kInboxLimit = 256;
constexpr std::size_t kMaxSubscriptions = 16;
constexpr std::size_t kMaxQueuedMessages = 1024;
// Fairness: per connection and poll round, at most one read of kReadChunk
// bytes and kRequestsPerRound requests handled; the rest waits for the next
// round, after every other client's turn. A connection is read from only
// once the requests it already sent are handled, so it holds at most one
// chunk and one partial request, and one that lets more than
// kMaxQueuedReplies replies pile up unread is closed.
constexpr std::size_t kReadChunk = 64 * 1024;
constexpr std::size_t kRequestsPerRound = 32;
constexpr std::size_t kMaxQueuedReplies = 256;
constexpr std::size_t kAcceptsPerRound = 32;

AccessOptions access_options(const ServerOptions& o) {
  AccessOptions a;
  a.max_unix = o.max_clients;
  a.max_tcp = o.max_tcp_clients;
  a.max_per_peer = o.max_clients_per_peer;
  a.read_token = o.token;
  a.control_token = o.control_token;
  a.control_gid = o.control_gid;
  a.owner_uid = ::geteuid();
  a.requests_per_second = o.peer_request_rate;
  a.connects_per_second = o.peer_connect_rate;
  return a;
}

Bytes encoded(const protocol::Message& m) {
  return std::make_shared<const std::vector<std::uint8_t>>(protocol::encode(m));
}

// The one message `wire` holds (bytes this daemon encoded).
protocol::Message decoded(const std::vector<std::uint8_t>& wire) {
  protocol::MessageReader reader;
  reader.feed(wire.data(), wire.size());
  auto m = reader.next();
  if (!m || reader.buffered() != 0) throw protocol::ProtocolError("an encoded event is not one whole message");
  return std::move(*m);
}

std::string unknown_stream(const std::string& s) {
  std::string names;
  for (const auto& n : protocol::stream_names()) names += (names.empty() ? "" : ", ") + n;
  return "unknown stream \"" + s + "\" (" + names + ")";
}

}  // namespace

struct Server::Connection {
  std::uint64_t id = 0;
  protocol::Fd fd;
  Peer peer;                         // (peer.tcp: which socket it came in on)
  Role role = Role::kRead;           // Unix: from the peer at accept; TCP: from the token at hello
  Role admitted_role = Role::kRead;  // the role its slot was counted with (released with it)
  bool tcp_reader = false;           // TCP: counted among the reading hellos (released with it)
  bool ready = false;                // hello done
  bool closing = false;              // close once the queue is written (a refused hello's reply)
  std::uint64_t accepted_ns = 0;
  std::uint64_t last_request_ns = 0;   // the last request handled (hello included)
  std::uint64_t last_progress_ns = 0;  // the last time its queue was empty or a send took bytes
  protocol::MessageReader reader{protocol::kMaxRequestPayloadBytes};
  struct Queued {
    Bytes bytes;
    bool event;  // droppable: an event, not a hello or reply
  };
  std::deque<Queued> out;
  std::size_t out_offset = 0, out_bytes = 0;
  std::size_t replies = 0;  // queued messages that are not events
  std::set<std::string> streams;
  std::uint64_t dropped = 0;
  bool dead = false;
  bool more = false;            // requests may be left to handle from an earlier read
  std::uint64_t resume_ns = 0;  // with more: its peer's request rate holds them until then
};

Server::Server(ServerOptions options, Handler handler)
    : options_(std::move(options)), handler_(std::move(handler)), access_(access_options(options_)) {
  if (!options_.socket_path.empty()) {
    unix_ = protocol::listen_unix(options_.socket_path, options_.socket_mode);
    // The file we bound, to remove it at the end only if it is still this one.
    struct stat st {};
    if (::lstat(options_.socket_path.c_str(), &st) == 0) socket_file_ = {st.st_dev, st.st_ino};
  }
  if (!options_.tcp.empty()) {
    if (options_.token.empty())
      throw std::invalid_argument("TCP needs a token (token_file): without one anybody on the network could connect");
    // Port 0 (any free port, tcp_port() says which) is valid for listening
    // only: parse_address refuses it, as a client cannot connect to it.
    const std::string& spec = options_.tcp;
    const bool any_port = spec.size() >= 2 && spec.compare(spec.size() - 2, 2, ":0") == 0;
    const auto a = protocol::parse_address(any_port ? spec.substr(0, spec.size() - 1) + "1" : spec);
    if (!a.tcp) throw std::invalid_argument("tcp must be HOST:PORT, got \"" + options_.tcp + "\"");
    if (!options_.control_token.empty() && options_.control_token == options_.token)
      throw std::invalid_argument("the control token must differ from the reading token");
    tcp_ = protocol::listen_tcp(a.host, any_port ? 0 : a.port);
    tcp_port_ = protocol::local_port(tcp_.get());
    if (a.host != "localhost" && a.host.rfind("127.", 0) != 0)
      logger(LogCategory::kServer)
          .warn(
              "TCP listens on {}: reachable from the network, where the token is all that stands between the "
              "box and anyone (use 127.0.0.1 and a tunnel unless you mean it)",
              options_.tcp);
  }
  if (!unix_ && !tcp_) throw std::invalid_argument("no socket to listen on (give a socket path or tcp)");
}

Server::~Server() {
  // (Another daemon may have replaced the path since: its socket stays.)
  struct stat st {};
  if (unix_ && !options_.socket_path.empty() && ::lstat(options_.socket_path.c_str(), &st) == 0 &&
      std::make_pair(st.st_dev, st.st_ino) == socket_file_)
    ::unlink(options_.socket_path.c_str());
}

void Server::wake() { wake_fd_.wake(); }

void Server::forget(const std::string& stream) {
  std::lock_guard<std::mutex> lock(inbox_mutex_);
  latest_.erase(stream);
}

void Server::publish(const std::string& stream, const protocol::Message& message) {
#ifndef NDEBUG
  // What this build publishes follows the schema to the letter (debug builds and the tests).
  protocol::check_event(message, true);
#endif
  // (Encoded once for `latest` and the subscribers alike, and not at all when neither wants it.)
  if (!protocol::pollable_stream(stream) && !has_subscribers(stream)) return;
  keep_and_queue(stream, encoded(message));
}

void Server::publish(const std::string& stream, std::vector<std::uint8_t> wire) {
#ifndef NDEBUG
  protocol::check_event(decoded(wire), true);
#endif
  keep_and_queue(stream, std::make_shared<const std::vector<std::uint8_t>>(std::move(wire)));
}

void Server::keep_and_queue(const std::string& stream, const Bytes& bytes) {
  {
    std::lock_guard<std::mutex> lock(inbox_mutex_);
    if (protocol::pollable_stream(stream)) latest_[stream] = bytes;  // kept for `latest`, subscribers or not
    if (subscribed_.count(stream) == 0) return;
    if (inbox_.size() >= kInboxLimit) {
      inbox_.erase(inbox_.begin());
      ++inbox_dropped_;
    }
    inbox_.emplace_back(stream, bytes);
  }
  wake();
}

bool Server::has_subscribers(const std::string& stream) const {
  std::lock_guard<std::mutex> lock(inbox_mutex_);
  return subscribed_.count(stream) > 0;
}

void Server::refresh_subscriptions() {
  std::set<std::string> all;
  for (const auto& [id, c] : connections_) all.insert(c->streams.begin(), c->streams.end());
  std::lock_guard<std::mutex> lock(inbox_mutex_);
  subscribed_ = std::move(all);
}

void Server::note(const char* kind, spdlog::level::level_enum level, const std::string& text) {
  std::uint64_t held_back = 0;
  if (!log_limiter_.allow(kind, protocol::monotonic_ns(), held_back)) {
    log_suppressed_ = log_limiter_.total_suppressed();
    return;
  }
  if (held_back > 0) {
    logger(LogCategory::kServer).log(level, "{} ({} more like it in the last interval not logged)", text, held_back);
  } else {
    logger(LogCategory::kServer).log(level, "{}", text);
  }
}

void Server::accept_from(int listener, bool tcp) {
  // A bounded number a round: a client connecting as fast as it can must not
  // keep the server accepting (the rest wait in the backlog for the next round).
  for (std::size_t k = 0; k < kAcceptsPerRound; ++k) {
    RateBucket& budget = tcp ? tcp_accepts_ : unix_accepts_;
    if (!budget.refill(Server::kAcceptsPerSecond, Server::kAcceptsPerSecond, protocol::monotonic_ns())) break;
    budget.tokens -= 1.0;
    protocol::Fd fd(::accept4(listener, nullptr, nullptr, SOCK_NONBLOCK | SOCK_CLOEXEC));
    if (!fd) {  // EAGAIN: nothing more waiting (or a transient error)
      budget.tokens += 1.0;
      break;
    }
    Peer peer;
    try {
      peer = peer_of(fd.get(), tcp);
    } catch (const std::exception& e) {  // (gone already)
      ++rejected_;
      note("refuse", spdlog::level::warn, std::string("refusing a client: ") + e.what());
      continue;
    }
    if (!access_.take_connect(peer, protocol::monotonic_ns())) {
      ++rejected_;
      note("refuse", spdlog::level::warn, "refusing a client: " + peer.key() + " connects too often");
      continue;
    }
    // (a Unix peer's role is known now; a TCP one reads until its hello's token says otherwise)
    const Role role = tcp ? Role::kRead : access_.unix_role(peer);
    if (const std::string why = access_.admit(peer, role); !why.empty()) {
      ++rejected_;
      note("refuse", spdlog::level::warn, "refusing a client: " + why);
      continue;  // closes it
    }
    if (tcp) {
      // Events are small and frequent: without this, Nagle holds one back
      // until the client acknowledges the last, which a delayed ACK can make
      // 40 ms (the TCP subscriber's p99 was 12 ms where the Unix one's was 3).
      const int one = 1;
      ::setsockopt(fd.get(), IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
    }
    auto c = std::make_unique<Connection>();
    c->id = next_id_++;
    c->fd = std::move(fd);
    c->peer = std::move(peer);
    c->role = role;
    c->admitted_role = role;
    c->accepted_ns = c->last_request_ns = c->last_progress_ns = protocol::monotonic_ns();
    protocol::Hello h;
    h.server = options_.server_name;
    h.capabilities = options_.capabilities;
    h.auth_required = tcp;
    enqueue(*c, encoded(protocol::encode_hello(h)), false);
    ++accepted_;
    note("connect", spdlog::level::info, "client " + std::to_string(c->id) + " connected (" + c->peer.key() + ")");
    connections_.emplace(c->id, std::move(c));
  }
  count_clients();
}

void Server::count_clients() {
  clients_ = connections_.size();
  unix_clients_ = access_.unix_clients();
  unix_readers_ = access_.unix_readers();
  tcp_readers_ = access_.tcp_readers();
  tcp_clients_ = access_.tcp_clients();
}

void Server::enqueue(Connection& c, Bytes bytes, bool event) {
  // Over budget: drop the oldest events (never the message half written, never
  // a hello or reply: a client waits for those). A client whose queue is full
  // of replies does not read what it asked for: it is closed.
  while (!c.out.empty() &&
         (c.out_bytes + bytes->size() > options_.max_queue_bytes || c.out.size() >= kMaxQueuedMessages)) {
    std::size_t victim = c.out_offset > 0 ? 1 : 0;
    while (victim < c.out.size() && !c.out[victim].event) ++victim;
    if (victim >= c.out.size()) {
      if (event) {  // nothing older to drop: this one goes
        ++c.dropped;
        ++dropped_events_;
        return;
      }
      note("unread", spdlog::level::warn, "client " + std::to_string(c.id) + ": does not read its replies; closing it");
      c.dead = true;
      return;
    }
    c.out_bytes -= c.out[victim].bytes->size();
    c.out.erase(c.out.begin() + static_cast<std::ptrdiff_t>(victim));  // (an event: replies unchanged)
    ++c.dropped;
    ++dropped_events_;
  }
  if (!event && c.replies >= kMaxQueuedReplies) {
    note("unread", spdlog::level::warn,
         "client " + std::to_string(c.id) + ": " + std::to_string(c.replies) + " replies unread; closing it");
    c.dead = true;
    return;
  }
  if (c.out.empty()) c.last_progress_ns = protocol::monotonic_ns();  // (the wait for the client starts now)
  c.out_bytes += bytes->size();
  if (!event) ++c.replies;
  c.out.push_back({std::move(bytes), event});
}

void Server::reply(Connection& c, const protocol::Reply& r) {
  // A client refuses an error text over kMaxTextBytes (and drops the
  // connection): cut a long one (load_table quoting a long path, twice) at a
  // UTF-8 character boundary.
  if (r.error.size() > protocol::kMaxTextBytes) {
    protocol::Reply cut = r;
    std::size_t n = protocol::kMaxTextBytes - 3;
    while (n > 0 && (static_cast<unsigned char>(cut.error[n]) & 0xC0) == 0x80) --n;
    cut.error.resize(n);
    cut.error += "...";
    return enqueue(c, encoded(protocol::encode_reply(cut)), false);
  }
  enqueue(c, encoded(protocol::encode_reply(r)), false);
}

void Server::handle(Connection& c, const protocol::Message& m) {
  const protocol::Request req = protocol::decode_request(m);  // ProtocolError closes the connection
  protocol::Reply r;
  r.id = req.id;
  auto refuse = [&](const char* code, const std::string& why, bool close) {
    r.ok = false;
    r.code = code;
    r.error = why;
    reply(c, r);
    c.closing = c.closing || close;
  };
  if (!c.ready) {
    if (req.cmd != "hello") return refuse(protocol::codes::kHelloFirst, "send hello first", true);
    const auto& args = req.args;
    if (!args.contains("protocol") || !args["protocol"].is_number_unsigned() ||
        args["protocol"].get<std::uint64_t>() != protocol::kProtocolVersion)
      return refuse(protocol::codes::kVersion,
                    "this daemon speaks protocol version " + std::to_string(protocol::kProtocolVersion), true);
    if (c.peer.tcp) {
      const std::string token =
          args.contains("token") && args["token"].is_string() ? args["token"].get<std::string>() : "";
      std::uint64_t wait_ms = 0;
      switch (access_.check_token(c.peer.address, token, protocol::monotonic_ns(), wait_ms)) {
        case ClientAccess::Verdict::kThrottled:
          ++auth_throttled_;
          return refuse(protocol::codes::kAuth,
                        "too many wrong tokens from " + c.peer.address + ": the next is looked at in " +
                            std::to_string(wait_ms) + " ms",
                        true);
        case ClientAccess::Verdict::kWrong:
          ++auth_failures_;
          note("auth", spdlog::level::warn,
               "client " + std::to_string(c.id) + " (" + c.peer.key() + "): wrong or missing token");
          return refuse(protocol::codes::kAuth, "a TCP client must send the daemon's token", true);
        case ClientAccess::Verdict::kControl: c.role = Role::kControl; break;
        case ClientAccess::Verdict::kRead: {
          c.role = Role::kRead;
          if (const std::string why = access_.admit_tcp_reader(); !why.empty()) {
            ++rejected_;
            note("refuse", spdlog::level::warn, "refusing client " + std::to_string(c.id) + ": " + why);
            return refuse(protocol::codes::kFull, why, true);
          }
          c.tcp_reader = true;
          break;
        }
      }
    }
    c.ready = true;
    logger(LogCategory::kServer)
        .debug("client {} ({}): hello done, protocol {}.{}, role {}", c.id, c.peer.key(), protocol::kProtocolVersion,
               protocol::kProtocolMinor, role_name(c.role));
    r.result = {{"protocol", protocol::kProtocolVersion},
                {"minor", protocol::kProtocolMinor},
                {"client_id", c.id},
                {"role", role_name(c.role)}};
    return reply(c, r);
  }
  if (c.role != Role::kControl && !is_reading_command(req.cmd)) {
    ++not_permitted_;
    note("permission", spdlog::level::warn,
         "client " + std::to_string(c.id) + " (" + c.peer.key() + "): \"" + req.cmd + "\" refused, it may only read");
    return refuse(protocol::codes::kPermission,
                  "\"" + req.cmd + "\" needs the control role (" +
                      (c.peer.tcp ? "the control token" : "the daemon's user or its control group") +
                      "); this connection may only read",
                  false);
  }
  if (req.cmd == "hello") return refuse(protocol::codes::kInvalidArgument, "hello was already done", false);
  if (req.cmd == "subscribe" || req.cmd == "unsubscribe") {
    std::vector<std::string> streams;
    try {
      streams = req.args.contains("streams")
                    ? protocol::get_string_list(req.args, "streams", kMaxSubscriptions, protocol::kMaxNameBytes)
                    : std::vector<std::string>{};
    } catch (const protocol::ProtocolError& e) {
      return refuse(protocol::codes::kInvalidArgument, e.what(), false);
    }
    for (const auto& s : streams)
      if (!protocol::valid_stream(s)) return refuse(protocol::codes::kInvalidArgument, unknown_stream(s), false);
    if (req.cmd == "subscribe") {
      c.streams.insert(streams.begin(), streams.end());
    } else if (streams.empty()) {
      c.streams.clear();
    } else {
      for (const auto& s : streams) c.streams.erase(s);
    }
    refresh_subscriptions();
    r.result = {{"streams", std::vector<std::string>(c.streams.begin(), c.streams.end())}};
    return reply(c, r);
  }
  if (req.cmd == "server_status") {
    r.result = status();
    return reply(c, r);
  }
  if (req.cmd == "latest") {  // the poll beside the watch: the stream's last event, if there was one
    std::string stream = "labels";
    try {
      if (req.args.contains("stream")) stream = protocol::get_string(req.args, "stream", protocol::kMaxNameBytes);
    } catch (const protocol::ProtocolError& e) {
      return refuse(protocol::codes::kInvalidArgument, e.what(), false);
    }
    if (!protocol::valid_stream(stream))
      return refuse(protocol::codes::kInvalidArgument, unknown_stream(stream), false);
    if (!protocol::pollable_stream(stream))
      return refuse(protocol::codes::kInvalidArgument,
                    "\"" + stream + "\" carries images: subscribe to it; `latest` serves the streams without", false);
    r.result = protocol::Json::object();
    Bytes last;
    {
      std::lock_guard<std::mutex> lock(inbox_mutex_);
      const auto it = latest_.find(stream);
      if (it != latest_.end()) last = it->second;
    }
    if (last) r.result["event"] = decoded(*last).meta;  // (none yet: left out)
    return reply(c, r);
  }
  // (The daemon's handler reports its own errors as replies; anything that
  // still escapes it is this request's failure, not the server thread's end.)
  protocol::Reply answer;
  try {
    answer = handler_(req);
  } catch (const std::exception& e) {
    note("handler", spdlog::level::err, "client " + std::to_string(c.id) + ": \"" + req.cmd + "\" failed: " + e.what());
    return refuse(protocol::codes::kFailed, std::string("the command failed: ") + e.what(), false);
  }
  reply(c, answer);
}

void Server::read_from(Connection& c, bool readable) {
  // Requests already read come first, then (if there is room) one read.
  // The peer's request rate may hold the rest back (until c.resume_ns).
  std::size_t handled = 0;
  bool held = false;
  const auto work = [&] {
    while (handled < kRequestsPerRound && !c.closing && !c.dead) {
      std::uint64_t wait_ns = 0;
      const std::uint64_t now = protocol::monotonic_ns();
      if (c.reader.buffered() > 0 && !access_.may_request(c.peer, now, wait_ns)) {
        held = true;
        c.resume_ns = now + wait_ns;
        return;
      }
      auto m = c.reader.next();
      if (!m) return;
      access_.count_request(c.peer);
      ++handled;
      c.last_request_ns = protocol::monotonic_ns();
      handle(c, *m);
    }
  };
  try {
    work();
    if (readable && !c.dead && !held && handled < kRequestsPerRound) {
      std::uint8_t buf[kReadChunk];
      ssize_t n;
      do {
        n = ::recv(c.fd.get(), buf, sizeof buf, 0);
      } while (n < 0 && errno == EINTR);
      if (n == 0 || (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK)) {
        c.dead = true;
        return;
      }
      // (After a refused hello the answer is on its way: the rest is ignored.)
      if (n > 0 && !c.closing) {
        c.reader.feed(buf, static_cast<std::size_t>(n));
        work();
      }
    }
  } catch (const protocol::ProtocolError& e) {
    ++protocol_errors_;
    note("protocol", spdlog::level::warn, "client " + std::to_string(c.id) + ": " + e.what() + "; closing it");
    c.dead = true;
  }
  // The budget ran out, or the rate held them: more requests may be waiting in the reader.
  c.more = !c.dead && !c.closing && (held || handled == kRequestsPerRound);
  if (!held) c.resume_ns = 0;
}

void Server::write_to(Connection& c) {
  while (!c.out.empty()) {
    const auto& front = *c.out.front().bytes;
    const ssize_t n = ::send(c.fd.get(), front.data() + c.out_offset, front.size() - c.out_offset, MSG_NOSIGNAL);
    if (n < 0) {
      if (errno == EAGAIN || errno == EWOULDBLOCK) return;
      if (errno == EINTR) continue;
      c.dead = true;
      return;
    }
    c.out_offset += static_cast<std::size_t>(n);
    c.last_progress_ns = protocol::monotonic_ns();
    if (c.out_offset == front.size()) {
      c.out_bytes -= front.size();
      if (!c.out.front().event) --c.replies;
      c.out.pop_front();
      c.out_offset = 0;
    }
  }
  if (c.closing) c.dead = true;
}

void Server::run(const std::atomic<bool>& stop) {
  std::vector<pollfd> fds;
  std::vector<std::uint64_t> ids;
  while (!stop.load()) {
    // Published messages to their subscribers.
    decltype(inbox_) batch;
    {
      std::lock_guard<std::mutex> lock(inbox_mutex_);
      batch.swap(inbox_);
    }
    for (auto& [stream, bytes] : batch)
      for (auto& [id, c] : connections_)
        if (c->ready && !c->closing && c->streams.count(stream)) enqueue(*c, bytes, true);

    fds.clear();
    ids.clear();
    const std::uint64_t before = protocol::monotonic_ns();
    std::uint64_t resume = before + 200'000'000ull;
    fds.push_back({wake_fd_.get(), POLLIN, 0});
    // (A listener out of budget is left out, -1: poll ignores it.)
    for (auto [listener, budget] : {std::pair{&unix_, &unix_accepts_}, std::pair{&tcp_, &tcp_accepts_}}) {
      if (!*listener) continue;
      const bool may_accept = budget->refill(Server::kAcceptsPerSecond, Server::kAcceptsPerSecond, before);
      if (!may_accept) resume = std::min(resume, before + budget->wait_ns(Server::kAcceptsPerSecond));
      fds.push_back({may_accept ? listener->get() : -1, POLLIN, 0});
    }
    const std::size_t first_client = fds.size();
    bool more = false;
    for (auto& [id, c] : connections_) {
      // Not read from while closing (the answer is on its way) or while it
      // has requests left (they come first). One its peer's rate holds is
      // not even watched for a hang-up until then, unless it has output.
      const bool held = c->more && c->resume_ns > before;
      const short events = static_cast<short>((c->closing || c->more ? 0 : POLLIN) | (c->out.empty() ? 0 : POLLOUT));
      fds.push_back({held && events == 0 ? -1 : c->fd.get(), events, 0});
      ids.push_back(id);
      more = more || (c->more && !held);
      if (held) resume = std::min(resume, c->resume_ns);
    }
    // (Requests left over from the last round: another round at once;
    // requests held by a rate: a round when the first may go.)
    const int timeout_ms = more ? 0 : static_cast<int>((resume - before + 999'999) / 1'000'000);
    const int r = ::poll(fds.data(), fds.size(), timeout_ms);
    if (r < 0 && errno != EINTR) throw protocol::SocketError("poll failed", errno);
    if (fds[0].revents & POLLIN) wake_fd_.drain();
    std::size_t k = 1;
    if (unix_ && (fds[k++].revents & POLLIN)) accept_from(unix_.get(), false);
    if (tcp_ && (fds[k++].revents & POLLIN)) accept_from(tcp_.get(), true);
    const std::uint64_t now = protocol::monotonic_ns();
    // Each round starts at the next connection: when a peer's request rate
    // lets one request through, its connections take turns (one of them
    // flooding cannot starve the others, a new client's hello included).
    const std::size_t n = fds.size() - first_client;
    const std::size_t start = n > 0 ? rotation_++ % n : 0;
    for (std::size_t j = 0; j < n; ++j) {
      const std::size_t i = first_client + (start + j) % n;
      auto it = connections_.find(ids[i - first_client]);
      if (it == connections_.end()) continue;
      Connection& c = *it->second;
      const bool readable = (fds[i].revents & (POLLIN | POLLHUP | POLLERR)) != 0;
      if (!c.dead && (readable || (c.more && c.resume_ns <= now))) read_from(c, readable);
      if (!c.ready && !c.dead &&
          now - c.accepted_ns > static_cast<std::uint64_t>(options_.hello_timeout_ms) * 1'000'000ull) {
        note("hello", spdlog::level::warn,
             "client " + std::to_string(c.id) + ": no hello within " + std::to_string(options_.hello_timeout_ms) +
                 " ms; closing it");
        c.dead = true;
      }
      if (c.ready && !c.dead && !c.closing && options_.idle_timeout_ms > 0) {
        const std::uint64_t idle_ns = static_cast<std::uint64_t>(options_.idle_timeout_ms) * 1'000'000ull;
        // (Both times may be later than `now`, taken before this round's reads.)
        const bool asks_nothing = c.streams.empty() && now > c.last_request_ns + idle_ns;
        const bool takes_nothing = !c.out.empty() && now > c.last_progress_ns + idle_ns;
        if (asks_nothing || takes_nothing) {
          ++idle_closed_;
          note("idle", spdlog::level::info,
               "client " + std::to_string(c.id) + ": " +
                   (asks_nothing ? "no request and no subscription" : "took nothing it was sent") + " for " +
                   std::to_string(options_.idle_timeout_ms / 1000) + " s; closing it");
          c.dead = true;
        }
      }
    }
    // Every queue with something in it is written now (replies queued while
    // reading go out without waiting for the next poll); then the dead go.
    for (auto& [id, c] : connections_)
      if (!c->dead && !c->out.empty()) write_to(*c);
    bool changed = false;
    for (auto it = connections_.begin(); it != connections_.end();) {
      Connection& c = *it->second;
      if (!c.dead) {
        ++it;
        continue;
      }
      note(
          "disconnect", spdlog::level::info,
          "client " + std::to_string(c.id) + " disconnected (" + std::to_string(c.dropped) + " events dropped for it)");
      access_.release(c.peer, c.admitted_role);
      if (c.tcp_reader) access_.release_tcp_reader();
      it = connections_.erase(it);
      changed = true;
    }
    if (changed) refresh_subscriptions();
    count_clients();
  }
}

nlohmann::json Server::status() const {
  return {{"clients", clients_.load()},
          {"unix_clients", unix_clients_.load()},
          {"unix_readers", unix_readers_.load()},
          {"tcp_readers", tcp_readers_.load()},
          {"tcp_clients", tcp_clients_.load()},
          {"accepted", accepted_.load()},
          {"rejected", rejected_.load()},
          {"protocol_errors", protocol_errors_.load()},
          {"auth_failures", auth_failures_.load()},
          {"auth_throttled", auth_throttled_.load()},
          {"not_permitted", not_permitted_.load()},
          {"idle_closed", idle_closed_.load()},
          {"dropped_events", dropped_events_.load() + inbox_dropped_.load()},
          {"log_suppressed", log_suppressed_.load()}};
}

}  // namespace tofmat::daemon
