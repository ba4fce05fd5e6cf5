#include "runtime/io/Exr.h"

#include "runtime/core/Error.h"
#include "runtime/io/AtomicFile.h"

#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <ImfOutputFile.h>
#include <ImfStdIO.h>
#include <half.h>

#include <array>
#include <exception>
#include <vector>

namespace qgi {
namespace {

constexpr std::array<const char*, 4> kChannelNames{"R", "G", "B", "A"};

// Far beyond any image this project writes; rejects absurd data windows before allocating.
constexpr long long kMaxPixels = 1ll << 28;

} // namespace

void writeExr(const std::filesystem::path& path, int width, int height,
              std::span<const float> pixels, int channels, ExrPrecision precision) {
    if (width <= 0 || height <= 0)
        fail("cannot write EXR '", path.string(), "': size ", width, "x", height);
    if (channels != 3 && channels != 4)
        fail("cannot write EXR '", path.string(), "': ", channels, " channels (need 3 or 4)");
    if (pixels.size() != std::size_t(width) * std::size_t(height) * std::size_t(channels))
        fail("cannot write EXR '", path.string(), "': ", pixels.size(), " values for ", width, "x",
             height, "x", channels);

    Imf::Header header(width, height);
    header.compression() = Imf::ZIP_COMPRESSION;
    // The writer takes slices of the file's own pixel type: halves are converted here.
    std::vector<Imath::half> halves;
    if (precision == ExrPrecision::Half) halves.assign(pixels.begin(), pixels.end());
    const Imf::PixelType type = precision == ExrPrecision::Float ? Imf::FLOAT : Imf::HALF;
    const std::size_t stride = std::size_t(channels) * (type == Imf::FLOAT ? 4 : 2);
    Imf::FrameBuffer frame;
    for (int c = 0; c < channels; ++c) {
        header.channels().insert(kChannelNames[c], Imf::Channel(type));
        const void* first = type == Imf::FLOAT ? static_cast<const void*>(pixels.data() + c)
                                               : static_cast<const void*>(halves.data() + c);
        frame.insert(kChannelNames[c], Imf::Slice::Make(type, first, header.dataWindow(), stride,
                                                        stride * std::size_t(width)));
    }
    Imf::StdOSStream encoded;
    try {
        Imf::OutputFile file(encoded, header);
        file.setFrameBuffer(frame);
        file.writePixels(height);
    } catch (const std::exception& e) {
        fail("cannot write EXR '", path.string(), "': ", e.what());
    }
    writeFileAtomically(path, encoded.str(), "EXR");
}

ImageF readExr(const std::filesystem::path& path) {
    try {
        Imf::InputFile file(path.c_str());
        const Imf::Header& header = file.header();
        const Imath::Box2i window = header.dataWindow();
        const long long width = static_cast<long long>(window.max.x) - window.min.x + 1;
        const long long height = static_cast<long long>(window.max.y) - window.min.y + 1;
        if (width <= 0 || height <= 0 || width * height > kMaxPixels)
            fail("cannot read EXR '", path.string(), "': data window ", width, "x", height);
        for (int c = 0; c < 3; ++c)
            if (!header.channels().findChannel(kChannelNames[c]))
                fail("cannot read EXR '", path.string(), "': no ", kChannelNames[c], " channel");

        ImageF image;
        image.width = int(width);
        image.height = int(height);
        image.rgba.resize(std::size_t(width * height) * 4);
        constexpr std::size_t stride = 4 * sizeof(float);
        Imf::FrameBuffer frame;
        for (int c = 0; c < 4; ++c) {
            const double fill = c == 3 ? 1.0 : 0.0; // a missing alpha reads as opaque
            frame.insert(kChannelNames[c],
                         Imf::Slice::Make(Imf::FLOAT, image.rgba.data() + c, window, stride,
                                          stride * std::size_t(width), 1, 1, fill));
        }
        file.setFrameBuffer(frame);
        file.readPixels(window.min.y, window.max.y);
        return image;
    } catch (const Error&) {
        throw;
    } catch (const std::exception& e) {
        fail("cannot read EXR '", path.string(), "': ", e.what());
    }
}

} // namespace qgi
