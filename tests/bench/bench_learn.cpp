// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// tofmat_bench_learn MODEL [LIBRARY] [RUNS] [TABLE]: a learned classifier's
// cost per query as tofmatd runs it (OnnxClassifier::classify, one query at a
// time, one thread), by sweep length, on windows of the table's curves (the
// one the model was trained for: default the real database's folder).
// Prints the median over RUNS (default 5) of each length's mean time per
// query, in microseconds. A benchmark: it never fails on timing.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <memory>
#include <string>
#include <vector>

#include "tofmat/core/exemplar_table.hpp"
#include "tofmat/core/table_file.hpp"
#include "tofmat/learn/onnx_classifier.hpp"

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s MODEL [LIBRARY] [RUNS] [TABLE]\n", argv[0]);
    return 2;
  }
  try {
    const std::string table_path = argc > 4 ? argv[4] : TOFMAT_DB_DIR;
    const auto table = std::make_shared<const tofmat::ExemplarTable>(tofmat::load_table(table_path));
    const std::string library = argc > 2 ? argv[2] : tofmat::learn::kDefaultOnnxruntimeLibrary;
    const int runs = argc > 3 ? std::max(1, std::atoi(argv[3])) : 5;
    const tofmat::learn::OnnxClassifier clf(table, argv[1], {}, library);
    const std::size_t n = table->elements_per_material(), bins = table->n_bins(), rows = table->n_rows();
    std::printf("learned classifier %s: host us per query (median of %d runs), one thread\n", argv[1], runs);
    for (const std::size_t length : {1, 3, 10, 30, 100}) {
      // Every material's window at a few positions.
      std::vector<std::vector<float>> queries;
      for (std::size_t m = 0; m < table->n_materials(); ++m)
        for (std::size_t start = 0; start + length <= bins; start += 37) {
          std::vector<float> q(n, std::nanf(""));
          bool any = false;
          for (std::size_t r = 0; r < rows; ++r)
            for (std::size_t b = start; b < start + length; ++b) {
              q[r * bins + b] = table->values()[m * n + r * bins + b];
              any |= !std::isnan(q[r * bins + b]);
            }
          if (any) queries.push_back(std::move(q));
        }
      std::vector<double> per_query;
      for (int run = 0; run < runs; ++run) {
        const auto t0 = std::chrono::steady_clock::now();
        for (const auto& q : queries) (void)clf.classify(q.data(), n);
        const std::chrono::duration<double, std::micro> dt = std::chrono::steady_clock::now() - t0;
        per_query.push_back(dt.count() / static_cast<double>(queries.size()));
      }
      std::sort(per_query.begin(), per_query.end());
      std::printf("  %3zu bins: %7.1f us (%zu queries)\n", length, per_query[per_query.size() / 2], queries.size());
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "tofmat_bench_learn: %s\n", e.what());
    return 1;
  }
  return 0;
}
