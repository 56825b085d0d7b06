// The consumer program of tests/consumer: uses the library the way a downstream project would
// (module umbrellas, stb-backed I/O linked through video3dgs::video3dgs, losses and metrics).
// Usage: video3dgs_consumer <scratch folder>. Exit status 0 on success.
#include <cstdio>
#include <filesystem>

#include <video3dgs/core.hpp>
#include <video3dgs/io.hpp>
#include <video3dgs/loss.hpp>
#include <video3dgs/metrics.hpp>

int main(int argc, char** argv) {
  using namespace video3dgs;
  if (argc < 2) return 2;
  static_assert(__cplusplus >= 202002L, "video3dgs::video3dgs must bring C++20 to its consumers");
  Image<float, 3> img(19, 11);
  for (std::size_t i = 0; i < img.size(); ++i) img.data()[i] = static_cast<float>(i % 256) / 255.0f;
  const auto png = std::filesystem::path(argv[1]) / "consumer.png";
  io::write_png(png, img);
  const auto back = io::read_image<3>(png);
  if (back.storage() != img.storage()) {
    std::fprintf(stderr, "PNG round trip differs\n");
    return 1;
  }
  ThreadPool pool(2);
  loss::L1DssimContext<float, 3> ctx;
  const float l = loss::l1_dssim_forward<float, 3>(img, back, ctx, &pool);
  const double s = metrics::ssim(img, back, &pool);
  if (l != 0.0f || s != 1.0) {
    std::fprintf(stderr, "loss %g ssim %g\n", static_cast<double>(l), s);
    return 1;
  }
  try {
    (void)io::read_image<3>(std::filesystem::path(argv[1]) / "missing.png");
    return 1;
  } catch (const io_error& e) {
    if (e.id() != "io.missing") return 1;
  }
  std::printf("video3dgs consumer: ok\n");
  return 0;
}
