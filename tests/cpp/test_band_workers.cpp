// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The threads that share a segmentation frame (band_workers.hpp): every band
// runs once per run(), on its own thread, errors come back to the caller and
// leave the workers ready for the next run, and destruction never hangs.
#include "tofmat/daemon/band_workers.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <set>
#include <stdexcept>
#include <thread>
#include <vector>

namespace {

using tofmat::daemon::BandWorkers;

TEST(BandWorkers, EveryBandRunsOnceARunOnItsOwnThread) {
  BandWorkers w(4);
  ASSERT_EQ(w.bands(), 4);
  for (int run = 0; run < 200; ++run) {
    std::vector<std::atomic<int>> calls(4);
    std::vector<std::thread::id> ids(4);
    w.run([&](int band) {
      ++calls[static_cast<std::size_t>(band)];
      ids[static_cast<std::size_t>(band)] = std::this_thread::get_id();
    });
    for (auto& c : calls) ASSERT_EQ(c.load(), 1) << "run " << run;
    EXPECT_EQ(ids[0], std::this_thread::get_id());  // band 0: the caller's
    EXPECT_EQ(std::set<std::thread::id>(ids.begin(), ids.end()).size(), 4u);
  }
}

TEST(BandWorkers, OneBandIsTheCallerAlone) {
  BandWorkers w(1);
  int calls = 0;
  w.run([&](int band) {
    EXPECT_EQ(band, 0);
    ++calls;
  });
  EXPECT_EQ(calls, 1);
}

TEST(BandWorkers, AnErrorReachesTheCallerAfterEveryBandAndTheNextRunWorks) {
  BandWorkers w(3);
  std::atomic<int> finished{0};
  EXPECT_THROW(w.run([&](int band) {
    if (band == 2) throw std::runtime_error("band 2 failed");
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    ++finished;
  }),
               std::runtime_error);
  EXPECT_EQ(finished.load(), 2);  // the others ran to their end before run() returned
  EXPECT_THROW(w.run([](int band) {
    if (band == 0) throw std::logic_error("the caller's band");
  }),
               std::logic_error);
  std::atomic<int> calls{0};
  w.run([&](int) { ++calls; });
  EXPECT_EQ(calls.load(), 3);
}

TEST(BandWorkers, DestroyedIdleOrRightAfterARun) {
  for (int k = 0; k < 50; ++k) {
    BandWorkers idle(3);  // never ran: its workers wait, and stop wakes them
    BandWorkers used(3);
    used.run([](int) {});
  }
}

TEST(BandWorkers, BandsForAThreadSetting) {
  EXPECT_EQ(BandWorkers::bands_for(3), 3);
  EXPECT_GE(BandWorkers::bands_for(0), 1);  // every core the system reports
  EXPECT_EQ(BandWorkers::bands_for(0), static_cast<int>(std::max(1u, std::thread::hardware_concurrency())));
  EXPECT_THROW(BandWorkers(0), std::invalid_argument);
}

}  // namespace
