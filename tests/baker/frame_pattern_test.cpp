// Frame patterns in paths and frame lists (baker/frame_pattern.h).
#include <gtest/gtest.h>

#include "baker/frame_pattern.h"
#include "baker/options.h"

using namespace lpm;

TEST(FramePattern, EveryConventionExpands) {
    EXPECT_EQ(expandFramePattern("smoke.####.vdb", 7), "smoke.0007.vdb");
    EXPECT_EQ(expandFramePattern("smoke.#.vdb", 1001), "smoke.1001.vdb");  // padding is a minimum
    EXPECT_EQ(expandFramePattern("smoke.@@@.vdb", 42), "smoke.042.vdb");
    EXPECT_EQ(expandFramePattern("smoke.@.vdb", 42), "smoke.42.vdb");
    EXPECT_EQ(expandFramePattern("smoke.%04d.vdb", 42), "smoke.0042.vdb");
    EXPECT_EQ(expandFramePattern("smoke.%d.vdb", 42), "smoke.42.vdb");
    EXPECT_EQ(expandFramePattern("smoke.$F4.vdb", 42), "smoke.0042.vdb");
    EXPECT_EQ(expandFramePattern("smoke.$F.vdb", 42), "smoke.42.vdb");
    EXPECT_EQ(expandFramePattern("shot_$F4/smoke.$F4.vdb", 3), "shot_0003/smoke.0003.vdb");  // every pattern
    EXPECT_EQ(expandFramePattern("smoke.####.vdb", -5), "smoke.-0005.vdb");
}

TEST(FramePattern, LookAlikesAreNotPatterns) {
    for (const char* p : {"smoke.vdb", "$FF.vdb", "$FOO/a.vdb", "100%.vdb", "%s.vdb", "%0d.vdb", "a$.vdb", "$F_a.vdb"})
    {
        EXPECT_FALSE(hasFramePattern(p)) << p;
        EXPECT_EQ(expandFramePattern(p, 3), p);
    }
    for (const char* p : {"a.####.vdb", "a.@.vdb", "a.%04d.vdb", "a.$F4.vdb", "a.$F.vdb", "$F.vdb"})
        EXPECT_TRUE(hasFramePattern(p)) << p;
}

TEST(FrameList, RangesStepsAndLists) {
    EXPECT_EQ(parseFrameList("1001-1004"), (std::vector<int>{1001, 1002, 1003, 1004}));
    EXPECT_EQ(parseFrameList("1-9x4"), (std::vector<int>{1, 5, 9}));
    EXPECT_EQ(parseFrameList("1-10x4"), (std::vector<int>{1, 5, 9}));
    EXPECT_EQ(parseFrameList("1,5,9-12"), (std::vector<int>{1, 5, 9, 10, 11, 12}));
    EXPECT_EQ(parseFrameList("7"), (std::vector<int>{7}));
    EXPECT_EQ(parseFrameList("3,1,2"), (std::vector<int>{3, 1, 2}));       // order kept
    EXPECT_EQ(parseFrameList("1-3,2-4"), (std::vector<int>{1, 2, 3, 4}));  // each frame once
    EXPECT_EQ(parseFrameList("-3--1"), (std::vector<int>{-3, -2, -1}));
}

TEST(FrameList, BadListsNameTheList) {
    for (const char* bad : {"", "a", "1-", "5-1", "1-5x0", "1-5x", "1,,2", "1;2", "1-5y2", "99999999999", "0-2000000"})
    {
        try {
            parseFrameList(bad);
            ADD_FAILURE() << "accepted '" << bad << "'";
        } catch (const UsageError& e) {
            EXPECT_NE(std::string(e.what()).find(std::string("'") + bad + "'"), std::string::npos) << e.what();
        }
    }
}

TEST(FrameList, FormatIsTheInverseForSortedFrames) {
    EXPECT_EQ(formatFrameList({}), "");
    EXPECT_EQ(formatFrameList({5}), "5");
    EXPECT_EQ(formatFrameList({7, 2, 5, 6, 1}), "1-2,5-7");
    for (const char* l : {"1-3,5,7-9", "-2-2,10", "1001-1100"}) EXPECT_EQ(formatFrameList(parseFrameList(l)), l);
}
