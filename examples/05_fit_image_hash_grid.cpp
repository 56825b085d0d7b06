// Fits an image with a 2D multiresolution hash grid + a linear head, trained with Adam.
//
//   example_05_fit_image_hash_grid <image.png|jpg> [steps = 100]
//
// Prints the PSNR every 10 steps. Shows the hash grid's forward/backward,
// a Linear head and Optimizer<float, Adam> with two parameter groups working together.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <vector>

#include "video3dgs/hash_grid.hpp"
#include "video3dgs/heads.hpp"
#include "video3dgs/io/image_io.hpp"
#include "video3dgs/optim.hpp"

int main(int argc, char** argv) try {
  using namespace video3dgs;
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s <image> [steps]\n", argv[0]);
    return 2;
  }
  const int steps = argc > 2 ? std::atoi(argv[2]) : 100;
  const Image<float, 3> img = io::read_image<3>(argv[1]);
  const std::size_t n = img.pixel_count();

  using Grid = HashGrid<float, 2, 16, 2, 17>;  // 16 levels x 2 features, 2^17 entries per level
  HashGridOptions go;
  go.per_level_scale = std::pow(std::max(img.width(), img.height()) / 16.0, 1.0 / 15);  // finest ~ 1 cell/pixel
  Grid grid(go);
  Linear<float, Grid::kOutputs, 3> head;

  std::vector<float> x(n * 2);  // pixel centres in [0, 1]^2
  for (int py = 0; py < img.height(); ++py)
    for (int px = 0; px < img.width(); ++px) {
      const std::size_t i = std::size_t(py) * std::size_t(img.width()) + std::size_t(px);
      x[2 * i] = (float(px) + 0.5f) / float(img.width());
      x[2 * i + 1] = (float(py) + 0.5f) / float(img.height());
    }
  BatchMatrix<float> target(Eigen::Index(n), 3);
  for (std::size_t i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) target(Eigen::Index(i), c) = img.data()[3 * i + std::size_t(c)];

  std::vector<float> grid_grad(grid.param_count()), head_grad(head.params().size());
  Optimizer<float, Adam> adam;
  Adam::Hyper hyper;
  hyper.beta2 = 0.99;
  adam.add_group({"table", LrSchedule::constant(2e-2), hyper, 2}, grid.params(), grid_grad);
  adam.add_group({"head", LrSchedule::constant(2e-2), hyper, 1}, head.params(), head_grad);

  ThreadPool pool;
  BatchMatrix<float> feat(Eigen::Index(n), Grid::kOutputs), y, dy, dfeat;
  for (int step = 0; step <= steps; ++step) {
    adam.zero_grad();
    grid.forward(x.data(), n, feat.data(), &pool);  // feature-major: exactly an N x 32 column-major matrix
    head.forward(feat, y);
    dy = y - target;
    if (step % 10 == 0 || step == steps) {
      const double mse = double(dy.squaredNorm()) / double(n * 3);
      std::printf("step %d: PSNR %.3f dB\n", step, -10 * std::log10(mse));
    }
    if (step == steps) break;
    dy *= 2.0f / float(n * 3);  // d(MSE)/dy
    dfeat.setZero(Eigen::Index(n), Grid::kOutputs);
    head.backward(feat, dy, head_grad, &dfeat);
    grid.backward(x.data(), n, dfeat.data(), grid_grad.data(), nullptr, &pool);
    adam.step(step, &pool);
  }
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "error: %s\n", e.what());
  return 1;
}
