// SHA-256 (FIPS 180-4) of a byte string, as the 64 lower-case hex digits `sha256sum` prints: the
// checksums a run records for its outputs and its checkpoints, checkable with coreutils.
#pragma once

#include <string>

namespace mgsr {

std::string Sha256Hex(const std::string& bytes);

// The same; `portable` true: without the processor's SHA instructions even where it has them
// (Sha256Hex uses them when it can; tests compare the two).
std::string Sha256HexWith(const std::string& bytes, bool portable);

}  // namespace mgsr
