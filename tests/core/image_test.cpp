#include "video3dgs/core/image.hpp"

#include <doctest/doctest.h>

using namespace video3dgs;

TEST_CASE_TEMPLATE("image: layout, views, crops and casts", Scalar, float, double) {
  Image<Scalar, 3> img(5, 4, Scalar(0.25));
  CHECK(img.width() == 5);
  CHECK(img.height() == 4);
  CHECK(img.stride() == 15);
  CHECK(img.size() == 60);
  img(2, 1, 2) = Scalar(0.75);
  CHECK(img.data()[1 * 15 + 2 * 3 + 2] == Scalar(0.75));
  ConstImageView<Scalar, 3> v = img.view();
  CHECK(v(2, 1, 2) == Scalar(0.75));
  auto crop = img.view().crop(1, 1, 3, 2);
  CHECK(crop.width() == 3);
  CHECK(crop.stride() == 15);
  CHECK(crop(1, 0, 2) == Scalar(0.75));
  crop(0, 0, 0) = Scalar(1);
  CHECK(img(1, 1, 0) == Scalar(1));
  const Image<Scalar, 3> copy = Image<Scalar, 3>::from_view(crop);
  CHECK(copy.stride() == 9);
  CHECK(copy(1, 0, 2) == Scalar(0.75));
  const auto d = img.template cast<double>();
  CHECK(d(2, 1, 2) == doctest::Approx(0.75));
  Image<Scalar, 1> empty;
  CHECK(empty.empty());
  CHECK(empty.view().empty());
}
