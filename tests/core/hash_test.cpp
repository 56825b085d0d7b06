// core/hash.hpp: FNV-1a 64 against the published test vectors, and the key's text form.
#include <doctest/doctest.h>

#include "video3dgs/core/hash.hpp"

using namespace video3dgs;

TEST_CASE("hash: FNV-1a 64 matches its published vectors; stable_key is 16 lowercase hex digits") {
  static_assert(fnv1a64("") == 0xcbf29ce484222325ull);  // the offset basis
  CHECK(fnv1a64("a") == 0xaf63dc4c8601ec8cull);
  CHECK(fnv1a64("foobar") == 0x85944171f73967e8ull);
  CHECK(stable_key("") == "cbf29ce484222325");
  CHECK(stable_key("foobar") == "85944171f73967e8");
  CHECK(stable_key("foobaR") != stable_key("foobar"));
  CHECK(stable_key(std::string("a\0b", 3)) != stable_key("a"));  // every byte counts
}
