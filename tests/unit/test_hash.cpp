// The shared FNV-1a hasher (runtime/core/Hash.h) against the published FNV-1a 64 test vectors,
// and the byte sequences its add/addArray helpers stand for (cache files depend on them); and
// the logger's printable(), which keeps hostile names from driving the terminal.
#include "runtime/core/Hash.h"

#include "runtime/core/Log.h"

#include <gtest/gtest.h>

#include <array>
#include <cstdint>
#include <cstring>
#include <string_view>
#include <vector>

namespace qgi {
namespace {

std::uint64_t hashOf(std::string_view text) {
    Fnv1aHasher h;
    h.addBytes(text.data(), text.size());
    return h.value();
}

TEST(Fnv1aHasher, MatchesThePublishedTestVectors) {
    EXPECT_EQ(hashOf(""), 0xcbf29ce484222325ull); // the offset basis
    EXPECT_EQ(hashOf("a"), 0xaf63dc4c8601ec8cull);
    EXPECT_EQ(hashOf("foobar"), 0x85944171f73967e8ull);
}

TEST(Fnv1aHasher, AddHashesTheValuesBytesInOrder) {
    const std::uint32_t word = 0x01020304u;
    const double real = -1.25;
    unsigned char bytes[sizeof word + sizeof real];
    std::memcpy(bytes, &word, sizeof word);
    std::memcpy(bytes + sizeof word, &real, sizeof real);
    Fnv1aHasher byValue, byBytes;
    byValue.add(word);
    byValue.add(real);
    byBytes.addBytes(bytes, sizeof bytes);
    EXPECT_EQ(byValue.value(), byBytes.value());
    Fnv1aHasher swapped;
    swapped.add(real);
    swapped.add(word);
    EXPECT_NE(swapped.value(), byValue.value()); // order matters
}

TEST(Fnv1aHasher, AddArrayHashesTheCountThenTheElements) {
    const std::vector<float> values{1.f, -2.f, 0.5f};
    Fnv1aHasher byArray, byHand;
    byArray.addArray(values);
    byHand.add(std::uint64_t(values.size()));
    byHand.addBytes(values.data(), values.size() * sizeof(float));
    EXPECT_EQ(byArray.value(), byHand.value());
    // Any contiguous range of the same elements hashes alike.
    const std::array<float, 3> same{1.f, -2.f, 0.5f};
    Fnv1aHasher byStdArray;
    byStdArray.addArray(same);
    EXPECT_EQ(byStdArray.value(), byArray.value());
    // The count keeps an empty array apart from no array at all.
    Fnv1aHasher empty, nothing;
    empty.addArray(std::vector<std::uint32_t>{});
    EXPECT_NE(empty.value(), nothing.value());
    EXPECT_EQ(empty.value(), [] {
        Fnv1aHasher h;
        h.add(std::uint64_t(0));
        return h.value();
    }());
}

} // namespace
} // namespace qgi

namespace qgi {
namespace {

TEST(Log, PrintableEscapesControlCharacters) {
    // A hostile name that would retitle the terminal, clear it and forge a line.
    EXPECT_EQ(printable("ok \x1b]0;owned\x07\x1b[2J\rqgi: fake\n"),
              "ok \\x1b]0;owned\\x07\\x1b[2J\\x0dqgi: fake\\x0a");
    EXPECT_EQ(printable("caf\xc3\xa9 \x7f"), "caf\xc3\xa9 \\x7f"); // UTF-8 passes, DEL does not
    EXPECT_EQ(printable("\xc2\x9b"
                        "31m"),
              "\\xc2\\x9b"
              "31m"); // UTF-8 CSI (a C1 control)
    EXPECT_EQ(printable(""), "");
}

} // namespace
} // namespace qgi
