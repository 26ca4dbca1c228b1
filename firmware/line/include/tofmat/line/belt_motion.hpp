// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Where the belt is (issue 17): a position along the belt, in mm, as a
// function of time, and when it will reach a position. Schedules are kept in
// belt positions, not in times, so that they follow the belt when it slows
// or stops (a fixed time delay misfires then):
//   FixedSpeed     a belt whose speed is known and constant
//   EncoderMotion  a quadrature encoder on the belt's pulley: the position
//                  is the count (forwards and backwards), the speed is
//                  estimated over a short window, and a belt that stops
//                  reaches nothing until it moves again
#pragma once
#include <cstdint>
#include <deque>
#include <limits>
#include <optional>

namespace tofmat::line {

class BeltMotion {
 public:
  virtual ~BeltMotion() = default;
  virtual double position_mm(std::uint64_t t_ns) const = 0;
  // The time the belt is predicted to reach `mm` (nullopt: not at the
  // present speed, e.g. stopped or running backwards). A time already past
  // when the position is behind.
  virtual std::optional<std::uint64_t> time_at(double mm, std::uint64_t now_ns) const = 0;
  virtual double speed_mm_s(std::uint64_t now_ns) const = 0;
};

class FixedSpeed : public BeltMotion {
 public:
  // Throws std::invalid_argument unless 0 < speed.
  explicit FixedSpeed(double mm_per_s);
  double position_mm(std::uint64_t t_ns) const override;
  std::optional<std::uint64_t> time_at(double mm, std::uint64_t now_ns) const override;
  double speed_mm_s(std::uint64_t) const override { return speed_; }

 private:
  double speed_;
};

// A two-channel (A/B) quadrature decoder, x4: every edge of either channel is
// a count, its sign from the other channel's level. An edge that skips a
// state (both changed: a lost event) is counted as an error, not guessed.
class Quadrature {
 public:
  // An edge on channel A (`b` false) or B, to `level`. Returns -1, 0 or +1.
  int edge(bool channel_b, bool level);
  void set_levels(bool a, bool b) {
    a_ = a;
    b_ = b;
  }
  std::int64_t count() const { return count_; }
  std::uint64_t errors() const { return errors_; }

 private:
  bool a_ = false, b_ = false;
  std::int64_t count_ = 0;
  std::uint64_t errors_ = 0;
};

class EncoderMotion : public BeltMotion {
 public:
  // counts_per_mm: 4 x pulses per revolution / (pi x pulley diameter).
  // window: how far back the speed is estimated from. stopped_after: no
  // count for this long and the belt is taken as stopped.
  // Throws std::invalid_argument for non-positive values.
  EncoderMotion(double counts_per_mm, std::uint64_t window_ns = 50'000'000,
                std::uint64_t stopped_after_ns = 100'000'000);
  // An edge of channel A or B at t_ns (in order).
  void edge(bool channel_b, bool level, std::uint64_t t_ns);
  void set_levels(bool a, bool b) { quad_.set_levels(a, b); }
  double position_mm(std::uint64_t t_ns) const override;
  std::optional<std::uint64_t> time_at(double mm, std::uint64_t now_ns) const override;
  double speed_mm_s(std::uint64_t now_ns) const override;
  const Quadrature& quadrature() const { return quad_; }

 private:
  double counts_per_mm_;
  std::uint64_t window_ns_, stopped_after_ns_;
  Quadrature quad_;
  struct Sample {
    std::uint64_t t_ns;
    std::int64_t count;
  };
  std::deque<Sample> samples_;  // counts within the window (and the one before it)
};

}  // namespace tofmat::line
