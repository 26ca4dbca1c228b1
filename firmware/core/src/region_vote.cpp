// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Region-level voting on a label map (region_vote.hpp).
#include "tofmat/core/region_vote.hpp"

#include <algorithm>
#include <cstdlib>
#include <stdexcept>

namespace tofmat {

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
  const auto h = static_cast<std::size_t>(height_);
  const auto k = static_cast<std::size_t>(classes_);
  // Per id, its pixels by label: classes_ slots and one for the pixels
  // without a label (their sum is the id's size). Counted during the scan:
  // ids only ever merge, so each region's counts are its ids' sums. Id 0 is
  // "no id" (an invalid pixel), so that every pixel's id indexes the tables.
  const std::size_t slots = k + 1;
  parent_.assign(1, 0);
  counts_.assign(slots, 0);
  // Two depths are on one surface when they differ by at most max_step
  // (64-bit: two int32 depths' difference may not fit 32 bits).
  const auto near = [&](std::size_t a, std::size_t b) {
    return std::llabs(static_cast<long long>(combined_q8[a]) - combined_q8[b]) <= max_step_q8_;
  };
  // One scan, a row at a time: each valid pixel takes its left neighbour's id
  // when it is on the same surface, else its upper neighbour's, else a new
  // one; when it is on the surface of both and their ids differ, the two ids
  // are joined in a union-find over the ids (not the pixels).
  std::fill(id_.begin(), id_.begin() + static_cast<std::ptrdiff_t>(w), 0u);  // (row 0's "upper" row, first)
  for (std::size_t y = 0; y < h; ++y) {
    const std::size_t row = y * w;
    // The upper row's ids: row 0 reads its own (zeroed) slots before writing them.
    const std::size_t up_row = y > 0 ? row - w : row;
    std::uint32_t left = 0;
    for (std::size_t x = 0; x < w; ++x) {
      const std::size_t i = row + x;
      if (flags[i] != 0) {
        id_[i] = left = 0;
        continue;
      }
      const std::uint32_t up = id_[up_row + x];
      std::uint32_t id;
      if (left != 0 && near(i, i - 1)) {
        id = left;
        // (an upper neighbour with the same id needs no depth test: nothing to join)
        if (up != 0 && up != left && near(i, up_row + x)) join(left, up);
      } else if (up != 0 && near(i, up_row + x)) {
        id = up;
      } else {
        id = static_cast<std::uint32_t>(parent_.size());
        parent_.push_back(id);
        counts_.resize(counts_.size() + slots, 0);
      }
      id_[i] = left = id;
      const std::uint8_t label = labels[i];
      ++counts_[id * slots + (label < k ? label : k)];
    }
  }
  // A region's counts gathered into its root's (the root is its oldest id).
  const std::size_t ids = parent_.size();
  for (std::size_t j = 1; j < ids; ++j) {
    const std::uint32_t r = find(static_cast<std::uint32_t>(j));
    if (r == j) continue;
    for (std::size_t c = 0; c < slots; ++c) counts_[r * slots + c] += counts_[j * slots + c];
  }
  // Each large region's label: the most frequent (ties: the lower), if it
  // holds at least half of the region's labelled pixels; kept per id (and
  // "none" for id 0), so that the relabelling looks up one table.
  winner_.assign(ids, static_cast<std::uint8_t>(classes_));
  voted_ = 0;
  for (std::size_t j = 1; j < ids; ++j) {
    if (parent_[j] != j) {
      winner_[j] = winner_[find(static_cast<std::uint32_t>(j))];  // (its root, older, is decided)
      continue;
    }
    const std::uint32_t* c = counts_.data() + j * slots;
    std::size_t best = 0, total = 0;
    for (std::size_t l = 0; l < k; ++l) {
      total += c[l];
      if (c[l] > c[best]) best = l;
    }
    if (total + c[k] < min_pixels_) continue;  // (its size: the labelled pixels and the others)
    if (total > 0 && 2 * static_cast<std::size_t>(c[best]) >= total) {
      winner_[j] = static_cast<std::uint8_t>(best);
      ++voted_;
    }
  }
  for (std::size_t i = 0; i < w * h; ++i) {
    const std::uint8_t v = winner_[id_[i]];
    labels[i] = v < k ? v : labels[i];
  }
}

}  // namespace tofmat
