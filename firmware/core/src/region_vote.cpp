// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Region-level voting on a label map (region_vote.hpp).
#include "tofmat/core/region_vote.hpp"

#include <cstdlib>
#include <limits>
#include <stdexcept>

namespace tofmat {
namespace {

constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();

}  // namespace

RegionVote::RegionVote(int width, int height, std::int32_t max_step_q8, std::size_t min_pixels, int classes)
    : width_(width), height_(height), max_step_q8_(max_step_q8), min_pixels_(min_pixels), classes_(classes) {
  if (width < 1 || height < 1) throw std::invalid_argument("region vote: the frame must be at least 1 x 1");
  if (max_step_q8 < 0) throw std::invalid_argument("region vote: the depth step must not be negative");
  if (min_pixels == 0) throw std::invalid_argument("region vote: a region needs at least one pixel");
  if (classes < 1 || classes > 255) throw std::invalid_argument("region vote: classes must be 1..255");
  id_.resize(static_cast<std::size_t>(width) * static_cast<std::size_t>(height));
}

std::uint32_t RegionVote::find(std::uint32_t i) {
  while (parent_[i] != i) {
    parent_[i] = parent_[parent_[i]];  // path halving
    i = parent_[i];
  }
  return i;
}

void RegionVote::join(std::uint32_t a, std::uint32_t b) {
  a = find(a);
  b = find(b);
  if (a < b) std::swap(a, b);
  parent_[a] = b;  // the older id stays the root
}

void RegionVote::apply(const std::int32_t* combined_q8, const std::uint8_t* flags, std::uint8_t* labels) {
  const auto w = static_cast<std::size_t>(width_);
  const std::size_t n = w * static_cast<std::size_t>(height_);
  // One scan: each valid pixel joins its left and upper neighbours when the
  // step in depth between them is at most max_step (64-bit: two int32 depths'
  // difference may not fit 32 bits); a pixel joining neither starts a new id,
  // and ids found to touch are joined in a union-find over the ids only.
  const auto near = [&](std::size_t a, std::size_t b) {
    return std::llabs(static_cast<long long>(combined_q8[a]) - combined_q8[b]) <= max_step_q8_;
  };
  parent_.clear();
  for (std::size_t i = 0; i < n; ++i) {
    if (flags[i] != 0) {
      id_[i] = kNone;
      continue;
    }
    const std::uint32_t left = i % w > 0 && id_[i - 1] != kNone && near(i, i - 1) ? id_[i - 1] : kNone;
    const std::uint32_t up = i >= w && id_[i - w] != kNone && near(i, i - w) ? id_[i - w] : kNone;
    if (left == kNone && up == kNone) {
      id_[i] = static_cast<std::uint32_t>(parent_.size());
      parent_.push_back(id_[i]);
    } else if (up == kNone) {
      id_[i] = left;
    } else {
      id_[i] = up;
      if (left != kNone && left != up) join(left, up);
    }
  }
  // Each id's region: its root's index among the roots.
  const std::size_t ids = parent_.size();
  region_.resize(ids);
  std::size_t regions = 0;
  for (std::size_t j = 0; j < ids; ++j) {
    const std::uint32_t r = find(static_cast<std::uint32_t>(j));  // r <= j: its region is known
    region_[j] = r == j ? static_cast<std::uint32_t>(regions++) : region_[r];
  }
  // Per region: its valid pixels and the count of each label.
  const auto k = static_cast<std::size_t>(classes_);
  size_.assign(regions, 0);
  counts_.assign(regions * k, 0);
  for (std::size_t i = 0; i < n; ++i) {
    if (id_[i] == kNone) continue;
    const std::uint32_t r = region_[id_[i]];
    ++size_[r];
    if (labels[i] < classes_) ++counts_[r * k + labels[i]];
  }
  // Each large region's label: the most frequent (ties: the lower), if it
  // holds at least half of the region's labelled pixels.
  winner_.assign(regions, static_cast<std::uint8_t>(classes_));
  voted_ = 0;
  for (std::size_t r = 0; r < regions; ++r) {
    if (size_[r] < min_pixels_) continue;
    const std::uint32_t* c = counts_.data() + r * k;
    std::size_t best = 0, total = 0;
    for (std::size_t j = 0; j < k; ++j) {
      total += c[j];
      if (c[j] > c[best]) best = j;
    }
    if (total > 0 && 2 * static_cast<std::size_t>(c[best]) >= total) {
      winner_[r] = static_cast<std::uint8_t>(best);
      ++voted_;
    }
  }
  for (std::size_t i = 0; i < n; ++i) {
    if (id_[i] == kNone) continue;
    const std::uint8_t v = winner_[region_[id_[i]]];
    if (v < classes_) labels[i] = v;
  }
}

}  // namespace tofmat
