#include "mgsr/core/sha256.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <string>

namespace mgsr {
namespace {

// FIPS 180-4 examples and the padding boundaries (55, 56 and 64 bytes change the block count).
TEST(Sha256Test, MatchesPublishedDigests) {
  EXPECT_EQ(Sha256Hex(""), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
  EXPECT_EQ(Sha256Hex("abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  EXPECT_EQ(Sha256Hex("abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq"),
            "248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1");
  EXPECT_EQ(Sha256Hex(std::string(1000000, 'a')),
            "cdc76e5c9914fb9281a1c7e284d73e67f1809a48a497200e046d39ccc7112cd0");
  EXPECT_EQ(Sha256Hex(std::string(55, 'x')),
            "d5e285683cd4efc02d021a5c62014694958901005d6f71e89e0989fac77e4072");
  EXPECT_EQ(Sha256Hex(std::string(56, 'x')),
            "04c26261370ee7541549d16dee320c723e3fd14671e66a099afe0a377c16888e");
  EXPECT_EQ(Sha256Hex(std::string(64, '\0')),
            "f5a5fd42d16a20302798ef6ed309979b43003d2320d9f0e8ea9831a92759fb4b");
}

// The processor's SHA instructions (used where the CPU has them) and the portable rounds agree on
// every length around the block and padding boundaries, on bytes of every value. (On a CPU
// without them both calls take the portable path; the published digests above still check it.)
TEST(Sha256Test, ShaInstructionsAndPortableCodeAgree) {
  uint64_t state = 0x9e3779b97f4a7c15ULL;
  for (size_t n : {0, 1, 3, 55, 56, 63, 64, 65, 119, 120, 127, 128, 129, 1000, 4096, 100003}) {
    std::string bytes(n, '\0');
    for (char& c : bytes) {
      state = state * 6364136223846793005ULL + 1442695040888963407ULL;
      c = static_cast<char>(state >> 56);
    }
    EXPECT_EQ(Sha256HexWith(bytes, false), Sha256HexWith(bytes, true)) << n << " bytes";
  }
  EXPECT_EQ(Sha256HexWith(std::string(1000000, 'a'), true),
            "cdc76e5c9914fb9281a1c7e284d73e67f1809a48a497200e046d39ccc7112cd0");
}

}  // namespace
}  // namespace mgsr
