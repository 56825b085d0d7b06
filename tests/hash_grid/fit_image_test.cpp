// A 2D hash grid + linear head fitted to a real photograph with Adam (the classic instant-ngp
// gigapixel experiment, at small scale): proves forward, backward and the optimizer work together.
#include <chrono>
#include <cmath>
#include <vector>

#include <doctest/doctest.h>

#include "../test_data.hpp"
#include "video3dgs/hash_grid.hpp"
#include "video3dgs/heads.hpp"
#include "video3dgs/io/image_io.hpp"
#include "video3dgs/optim.hpp"

using namespace video3dgs;

TEST_CASE("hash grid + linear head fit a DAVIS frame to >= 30 dB PSNR" * doctest::test_suite("shared_data")) {
  const auto dir = test::shared_data_or_skip("blackswan/frames/00000.jpg");
  if (dir.empty()) return;
  const auto t0 = std::chrono::steady_clock::now();
  const Image<float, 3> img = io::read_image<3>(dir);
  const int w = img.width(), h = img.height();
  const std::size_t n = img.pixel_count();
  REQUIRE(n > 0);

  constexpr int kLevels = 16;
  using Grid = HashGrid<float, 2, kLevels, 2, 17>;
  HashGridOptions go;
  go.base_resolution = 16;
  go.per_level_scale = std::pow(double(std::max(w, h)) / 16.0, 1.0 / (kLevels - 1));  // finest level ~ one cell per pixel
  Grid grid(go);
  using Head = Linear<float, Grid::kOutputs, 3>;
  Head head;

  // Pixel centres in [0, 1]^2.
  std::vector<float> x(n * 2);
  for (int py = 0; py < h; ++py)
    for (int px = 0; px < w; ++px) {
      const std::size_t i = std::size_t(py) * std::size_t(w) + std::size_t(px);
      x[i * 2 + 0] = (float(px) + 0.5f) / float(w);
      x[i * 2 + 1] = (float(py) + 0.5f) / float(h);
    }
  BatchMatrix<float> target(Eigen::Index(n), 3);
  for (std::size_t i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) target(Eigen::Index(i), c) = img.data()[i * 3 + std::size_t(c)];

  std::vector<float> grid_grad(grid.param_count()), head_grad(Head::kParams);
  Optimizer<float, Adam> opt;
  Adam::Hyper hyper;
  hyper.beta2 = 0.99;
  opt.add_group({"table", LrSchedule::constant(2e-2), hyper, 2}, grid.params(), grid_grad);
  opt.add_group({"head", LrSchedule::constant(2e-2), hyper, 1}, head.params(), head_grad);

  ThreadPool pool(2);
  BatchMatrix<float> feat(Eigen::Index(n), Grid::kOutputs), y, dy, dfeat;
  double psnr = 0;
  int steps = 0;
  const int max_steps = 150;
  for (; steps < max_steps; ++steps) {
    opt.zero_grad();
    grid.forward(x.data(), n, feat.data(), &pool);
    head.forward(feat, y);
    dy = y - target;
    const double mse = double(dy.squaredNorm()) / double(n * 3);
    psnr = -10.0 * std::log10(std::max(mse, 1e-20));
    if (psnr >= 30.5) break;
    dy *= 2.0f / float(n * 3);
    dfeat.setZero(Eigen::Index(n), Grid::kOutputs);
    head.backward(feat, dy, head_grad, &dfeat);
    grid.backward(x.data(), n, dfeat.data(), grid_grad.data(), nullptr, &pool);
    opt.step(steps, &pool);
  }
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  MESSAGE("fit " << w << "x" << h << ": PSNR " << psnr << " dB after " << steps << " Adam steps, " << secs << " s");
  CHECK(psnr >= 30.0);
  CHECK(steps <= 45);  // reached 30.5 dB in 38 Adam steps (measured 2026-11-23); the loop's cap (150) cannot fail
}
