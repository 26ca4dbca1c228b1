// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// SortingLine: outlet specs, the GPIO backend, and the line's thread running the Sorter on barrier edges and labels.
#include "tofmat/daemon/sorting_line.hpp"

#include <poll.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <set>

#include "spec_text.hpp"
#include "tofmat/daemon/log.hpp"
#include "tofmat/gpio/sim_gpio.hpp"

namespace tofmat::daemon {
namespace {

double number(const std::string& key, const std::string& value, const std::string& outlet) {
  if (const auto v = whole_number(value)) return *v;
  throw std::invalid_argument("outlet \"" + outlet + "\": " + key + " \"" + value + "\" is not a number");
}

}  // namespace

std::shared_ptr<gpio::Backend> make_gpio_backend(const std::string& name) {
  if (name == "libgpiod") return gpio::make_libgpiod_backend();
  if (name == "sim") return gpio::SimGpio::create();
  throw std::invalid_argument("--gpio \"" + name + "\": libgpiod (the board's GPIO) or sim (a simulated chip)");
}

OutletOptions parse_outlet(const std::string& text) {
  const auto colon = text.find(':');
  if (colon == std::string::npos || colon == 0)
    throw std::invalid_argument(
        "outlet \"" + text + "\": expected NAME:position=MM,line=CHIP:LINE[,materials=a+b][,pulse=MS][,active_low=1]");
  OutletOptions o;
  o.outlet.name = text.substr(0, colon);
  bool has_position = false, has_line = false;
  for (const auto& part : split(text.substr(colon + 1), ',')) {
    const auto eq = part.find('=');
    if (eq == std::string::npos)
      throw std::invalid_argument("outlet \"" + o.outlet.name + "\": \"" + part + "\" is not key=value");
    const std::string key = part.substr(0, eq), value = part.substr(eq + 1);
    if (key == "position") {
      o.outlet.position_mm = number(key, value, o.outlet.name);
      has_position = true;
    } else if (key == "line") {
      o.line = gpio::LineSpec::parse(value);
      has_line = true;
    } else if (key == "materials") {
      for (const auto& name : split(value, '+'))
        if (!name.empty()) o.outlet.materials.push_back(name);
    } else if (key == "pulse") {
      const double ms = number(key, value, o.outlet.name);
      if (!(ms > 0 && ms <= 10'000))
        throw std::invalid_argument("outlet \"" + o.outlet.name + "\": pulse must be 0 to 10000 ms (not 0)");
      o.outlet.pulse_ns = ms_to_ns(ms);
    } else if (key == "active_low") {
      if (value != "0" && value != "1")
        throw std::invalid_argument("outlet \"" + o.outlet.name + "\": active_low is 0 or 1");
      o.active_low = value == "1";
    } else {
      throw std::invalid_argument("outlet \"" + o.outlet.name + "\": unknown key \"" + key +
                                  "\" (position, line, materials, pulse, active_low)");
    }
  }
  if (!has_position) throw std::invalid_argument("outlet \"" + o.outlet.name + "\": no position=MM");
  if (!has_line) throw std::invalid_argument("outlet \"" + o.outlet.name + "\": no line=CHIP:LINE");
  return o;
}

SortingLine::SortingLine(const LineOptions& options, std::shared_ptr<gpio::Backend> backend,
                         const std::vector<std::string>& materials, Hooks hooks)
    : options_(options),
      backend_(std::move(backend)),
      hooks_(std::move(hooks)),
      filter_({ms_to_ns(options.debounce_ms), ms_to_ns(options.min_gap_ms)}) {
  const auto bad = [](const std::string& what) { throw std::invalid_argument("sorting line: " + what); };
  if (options.barrier.empty()) bad("--line-barrier is needed (the light barrier's CHIP:LINE)");
  const bool encoder = !options.encoder_a.empty() || !options.encoder_b.empty();
  if (encoder == (options.speed_mm_s > 0))
    bad("give the belt's motion: --line-speed MM/S, or --line-encoder-a, --line-encoder-b and "
        "--line-encoder-counts-per-mm (one of the two)");
  if (encoder && (options.encoder_a.empty() || options.encoder_b.empty() || !(options.encoder_counts_per_mm > 0)))
    bad("an encoder needs --line-encoder-a, --line-encoder-b and a positive --line-encoder-counts-per-mm");
  for (const double v : {options.debounce_ms, options.min_gap_ms, options.margin_ms, options.alarm_hold_ms,
                         options.max_distance, options.camera_mm})
    if (!(v >= 0) || !std::isfinite(v)) bad("times, distances and --line-max-distance must be numbers >= 0");
  line::SorterConfig config;
  config.camera_mm = options.camera_mm;
  config.decision_margin_ns = ms_to_ns(options.margin_ms);
  config.alarm_hold_ns = ms_to_ns(options.alarm_hold_ms);
  std::vector<OutletOptions> outlets;
  for (const auto& text : options.outlets) outlets.push_back(parse_outlet(text));
  const std::set<std::string> known(materials.begin(), materials.end());
  for (std::size_t k = 0; k < outlets.size(); ++k) {
    for (const auto& m : outlets[k].outlet.materials)
      if (!known.count(m))
        bad("outlet \"" + outlets[k].outlet.name + "\" takes \"" + m + "\", which the table does not hold");
    if (outlets[k].outlet.name == options.reject) config.reject = k;
    config.outlets.push_back(outlets[k].outlet);
  }
  if (!options.reject.empty() && !config.reject) bad("--line-reject \"" + options.reject + "\" is not an outlet");
  line::validate(config);
  // The lines: every one asked for now, so that a wrong name fails at start.
  const std::string consumer = "tofmatd";
  barrier_ = backend_->request_input(gpio::LineSpec::parse(options.barrier),
                                     {options.barrier_active_low, gpio::parse_bias(options.barrier_bias)}, consumer);
  if (encoder) {
    enc_a_ = backend_->request_input(gpio::LineSpec::parse(options.encoder_a), {}, consumer);
    enc_b_ = backend_->request_input(gpio::LineSpec::parse(options.encoder_b), {}, consumer);
    auto m = std::make_unique<line::EncoderMotion>(options.encoder_counts_per_mm);
    m->set_levels(enc_a_->value(), enc_b_->value());
    encoder_ = m.get();
    motion_ = std::move(m);
  } else {
    motion_ = std::make_unique<line::FixedSpeed>(options.speed_mm_s);
  }
  for (const auto& o : outlets) outlets_.push_back(backend_->request_output(o.line, {o.active_low, false}, consumer));
  if (!options.alarm.empty()) alarm_ = backend_->request_output(gpio::LineSpec::parse(options.alarm), {}, consumer);

  line::Hooks h;
  h.start_burst = [this](std::uint64_t item) -> std::optional<std::uint64_t> {
    std::string why;
    const auto t = hooks_.start_burst ? hooks_.start_burst(why) : std::nullopt;
    if (!t) publish_line("burst", "item " + std::to_string(item) + ": no burst (" + why + ")");
    return t;
  };
  h.drive = [this](std::size_t outlet, bool on) {
    try {
      outlets_.at(outlet)->set(on);
    } catch (const std::exception& e) {
      publish_line("gpio", e.what());
    }
  };
  h.alarm = [this](bool on) {
    if (alarm_) {
      try {
        alarm_->set(on);
      } catch (const std::exception& e) {
        publish_line("gpio", e.what());
      }
    }
    publish_line("alarm", on ? "on" : "off");
  };
  h.event = [this](const line::SortEvent& e) { publish_sort(e); };
  h.fault = [this](const std::string& kind, const std::string& message) { publish_line(kind, message); };
  sorter_ = std::make_unique<line::Sorter>(config, *motion_, std::move(h));
}

SortingLine::~SortingLine() = default;

void SortingLine::wake() { wake_fd_.wake(); }

void SortingLine::label(const protocol::LabelEvent& e) {
  if (!e.trigger || e.state == "tracking") return;
  line::BurstLabel l;
  l.trigger = *e.trigger;
  l.unknown = e.state == "unknown";
  l.out_of_range = e.state == "out_of_range";
  // An unknown burst has no material; its nearest is the ranking's first.
  l.material = e.state == "final" || e.state == "mixed" ? e.material
               : l.unknown && !e.ranking.empty()        ? e.ranking.front().material
                                                        : "";
  l.mixed = e.state == "mixed";
  l.distance = e.distance;
  l.confident = !l.material.empty() && (options_.max_distance <= 0 || e.distance <= options_.max_distance);
  if (e.truth) l.truth = e.truth->material;
  {
    std::lock_guard<std::mutex> lock(inbox_mutex_);
    if (labels_.size() < 1024) labels_.push_back(l);  // (the line thread takes them at once; a bound all the same)
  }
  wake();
}

void SortingLine::camera(bool streaming) {
  {
    std::lock_guard<std::mutex> lock(inbox_mutex_);
    camera_ = streaming;
  }
  wake();
}

void SortingLine::handle_inbox(std::uint64_t now_ns) {
  std::vector<line::BurstLabel> labels;
  std::optional<bool> camera;
  {
    std::lock_guard<std::mutex> lock(inbox_mutex_);
    labels.swap(labels_);
    camera.swap(camera_);
  }
  if (camera) sorter_->camera(*camera, now_ns);
  for (const auto& l : labels) sorter_->label(l, now_ns);
}

void SortingLine::publish_sort(const line::SortEvent& e) {
  protocol::Message m;
  m.meta = {{"event", "sort"},
            {"state", e.state},
            {"item", e.item},
            {"trigger_ns", e.trigger_ns},
            {"material", e.material},
            {"distance", e.distance},
            {"outlet", e.outlet},
            {"reason", line::reason_name(e.reason)},
            {"decided_ns", e.decided_ns},
            {"margin_ms", e.margin_ms}};
  if (e.fire_ns) m.meta["fire_ns"] = *e.fire_ns;  // (absent: no pusher, or the belt stands)
  // (simulated items only: the belt's own item when it knows it, else what the burst saw)
  const std::optional<std::string> truth = hooks_.item_truth ? hooks_.item_truth(e.trigger_ns) : std::nullopt;
  if (truth)
    m.meta["truth"] = *truth;
  else if (e.truth)
    m.meta["truth"] = *e.truth;
  // A client that reads this event and then asks for status sees it counted.
  take_snapshot(protocol::monotonic_ns());
  if (hooks_.publish) hooks_.publish(m, "sort");
}

void SortingLine::publish_line(const std::string& kind, const std::string& message) {
  if (kind == "alarm")
    logger(LogCategory::kLine).warn("sorting line: alarm {}", message);
  else
    logger(LogCategory::kLine).warn("sorting line: {}: {}", kind, message);
  const std::uint64_t now = protocol::monotonic_ns();
  protocol::Message m;
  m.meta = {{"event", "line"},
            {"kind", kind},
            {"message", message.substr(0, protocol::kMaxTextBytes)},
            {"alarm", sorter_ ? sorter_->alarm_on() : false},
            {"timestamp_ns", now}};
  take_snapshot(now);  // (as for a sort event: status counts what a client has read)
  if (hooks_.publish) hooks_.publish(m, "line");
}

void SortingLine::run(const std::atomic<bool>& stop) {
  struct Edge {
    std::uint64_t t;
    int source;  // 0 barrier, 1 encoder A, 2 encoder B
    bool rising;
  };
  std::vector<gpio::EdgeEvent> got;
  std::vector<Edge> edges;
  std::vector<pollfd> fds{{wake_fd_.get(), POLLIN, 0}, {barrier_->fd(), POLLIN, 0}};
  if (enc_a_) fds.push_back({enc_a_->fd(), POLLIN, 0});
  if (enc_b_) fds.push_back({enc_b_->fd(), POLLIN, 0});
  while (!stop.load()) {
    std::uint64_t now = protocol::monotonic_ns();
    // Wake for the schedule's next step (to the nanosecond: ppoll), and at
    // least every 200 ms (status, stop).
    std::uint64_t until = now + 200'000'000ull;
    if (const auto w = sorter_->next_wake(now)) until = std::min(until, *w);
    if (const auto d = filter_.next_deadline()) until = std::min(until, *d);
    protocol::poll_until(fds.data(), fds.size(), until);
    if (fds[0].revents & POLLIN) wake_fd_.drain();
    // Every input's edges, in the order they happened (the barrier's item
    // needs the belt's position at its edge).
    edges.clear();
    const auto take = [&](gpio::InputLine* in, int source) {
      if (!in) return;
      got.clear();
      in->read_events(got, 256);
      for (const auto& e : got) edges.push_back({e.timestamp_ns, source, e.rising});
    };
    take(barrier_.get(), 0);
    take(enc_a_.get(), 1);
    take(enc_b_.get(), 2);
    std::stable_sort(edges.begin(), edges.end(), [](const Edge& a, const Edge& b) { return a.t < b.t; });
    now = protocol::monotonic_ns();
    for (const auto& e : edges) {
      if (e.source == 0) {
        if (const auto item = filter_.edge(e.t, e.rising)) sorter_->item(*item, now);
      } else if (encoder_) {
        encoder_->edge(e.source == 2, e.rising, e.t);
      }
    }
    if (const auto item = filter_.advance(now)) sorter_->item(*item, now);
    handle_inbox(now);
    sorter_->poll(now);
    take_snapshot(now);
  }
}

void SortingLine::take_snapshot(std::uint64_t now_ns) {
  if (!sorter_) return;
  // (What status() reports, copied here; the JSON is built when asked for.)
  std::lock_guard<std::mutex> lock(status_mutex_);
  snapshot_ = {sorter_->counts(),
               sorter_->on_belt(),
               sorter_->alarm_on(),
               motion_->speed_mm_s(now_ns),
               filter_.glitches(),
               filter_.bounces(),
               encoder_ ? encoder_->quadrature().errors() : 0};
}

nlohmann::json SortingLine::status() const {
  std::lock_guard<std::mutex> lock(status_mutex_);
  const Snapshot& n = snapshot_;
  nlohmann::json s = {{"gpio", backend_->name()},    {"items", n.counts.items},
                      {"sorted", n.counts.sorted},   {"rejected", n.counts.rejected},
                      {"late", n.counts.late},       {"faults", n.counts.faults},
                      {"on_belt", n.on_belt},        {"alarm", n.alarm},
                      {"speed_mm_s", n.speed_mm_s},  {"barrier_glitches", n.glitches},
                      {"barrier_bounces", n.bounces}};
  if (encoder_) s["encoder_errors"] = n.encoder_errors;
  return s;
}

}  // namespace tofmat::daemon
